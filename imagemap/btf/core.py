"""The compressed BTF: truncated-SVD factors, directions and colour layout.

A BTF sampled at ``n_lights`` light and ``n_views`` view directions, with
``n_channels`` colour channels, is the matrix S of shape (n_rows, H*W) whose
rows are images (one per light x view x channel) and whose columns are the
unrolled apparent BRDFs of the texels. Its truncated SVD S ~ U Sigma V^T keeps
``k`` components:

* ``eigen_abrdfs`` U, (n_rows, k): orthonormal columns, the eigen-ABRDFs;
* ``singular_values`` sigma, (k,);
* ``eigentextures`` V Sigma, (H, W, k): the only part that extrapolation
  synthesizes (U is shared by the sample and the result).

Row order is C order over (light, view, channel)::

    row = (light * n_views + view) * n_channels + channel

Directions are (theta, phi) in degrees: theta is the polar angle from the
surface normal (0 = straight above), phi the azimuth, as in the Bonn BTF
files (which store radians).

Example
-------
>>> import numpy as np
>>> from imagemap.btf import compress, relative_error
>>> rng = np.random.default_rng(0)
>>> S = rng.random((2 * 1 * 3, 8 * 8), dtype=np.float32)   # 2 lights, 1 view, RGB
>>> btf = compress(S, shape=(8, 8), light_dirs=[[0, 0], [22, 90]], view_dirs=[[0, 0]], k=6)
>>> btf.image(light=1, view=0).shape
(8, 8, 3)
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from imagemap.io import InputError, read_npz, write_npz

__all__ = [
    "BTF",
    "compress",
    "relative_error",
    "check_directions",
    "directions_to_vectors",
]

#: Colour models a BTF's channels may be stored in (the Bonn DFMF files may use
#: decorrelated ones; :meth:`BTF.to_rgb` undoes them).
COLOR_MODELS = (
    "RGB",
    "YUV",
    "YCoCg",
    "PCA",
    "Ylog_UV",
    "Ylog_Ulog_Vlog",
    "Ylog_UdivY_VdivY",
    "logRGB",
)

# Inverse colour transforms of the Bonn BTF library (btflib, undecorrelate.m).
_YUV_TO_RGB = np.array(
    [[1.0, 0.0, 1.13983], [1.0, -0.39465, -0.5806], [1.0, 2.03211, 0.0]], dtype=np.float64
)
_YCOCG_TO_RGB = np.array([[1.0, 1.0, -1.0], [1.0, 0.0, 1.0], [1.0, -1.0, -1.0]], dtype=np.float64)


def directions_to_vectors(directions: np.ndarray) -> np.ndarray:
    """(theta, phi) in degrees, shape (n, 2), to unit vectors (n, 3), z = normal.

    Example
    -------
    >>> directions_to_vectors(np.array([[0.0, 0.0]]))
    array([[0., 0., 1.]])
    """
    directions = np.asarray(directions, dtype=np.float64).reshape(-1, 2)
    theta, phi = np.deg2rad(directions[:, 0]), np.deg2rad(directions[:, 1])
    return np.stack(
        [np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], axis=1
    )


#: Largest polar angle of a light or view direction (degrees): 90 is the horizon; a BTF
#: samples the hemisphere above the surface (the Bonn files reach 75).
MAX_THETA = 90.0


def check_directions(value, name: str) -> np.ndarray:
    """(n, 2) (theta, phi) degrees as float32, or InputError naming ``name``.

    theta must lie in [0, :data:`MAX_THETA`] and phi be finite: a NaN direction would be
    picked by :meth:`BTF.nearest_light` (every comparison with NaN is false).

    Example
    -------
    >>> check_directions([[22.0, 90.0]], "light_dirs").tolist()
    [[22.0, 90.0]]
    """
    array = np.asarray(value, dtype=np.float32)
    if array.ndim != 2 or array.shape[1] != 2 or array.shape[0] < 1:
        raise InputError(f"{name}: expected (n, 2) (theta, phi) in degrees, got {array.shape}")
    bad = ~np.isfinite(array).all(axis=1)
    if bad.any():
        raise InputError(
            f"{name}: direction {int(np.argmax(bad))} is not finite ({array[bad][0].tolist()})"
        )
    outside = (array[:, 0] < 0) | (array[:, 0] > MAX_THETA)
    if outside.any():
        index = int(np.argmax(outside))
        raise InputError(
            f"{name}: direction {index} has theta {float(array[index, 0]):g} degrees, "
            f"outside 0..{MAX_THETA:g} (the hemisphere above the surface)"
        )
    return array


@dataclass
class BTF:
    """A TSVD-compressed BTF (see the module docstring for the layout).

    Parameters
    ----------
    eigen_abrdfs : ndarray, (n_rows, k)
        U, orthonormal columns.
    singular_values : ndarray, (k,)
        sigma.
    eigentextures : ndarray, (H, W, k)
        V Sigma.
    light_dirs, view_dirs : ndarray, (n, 2)
        (theta, phi) in degrees of each light and view.
    channels : tuple of str
        Channel names, e.g. ("R", "G", "B").
    color_model : str
        One of :data:`COLOR_MODELS`; the channels' space.
    color_mean, color_matrix : ndarray
        Only for ``color_model="PCA"``: RGB = values @ color_matrix + color_mean.
    """

    eigen_abrdfs: np.ndarray
    singular_values: np.ndarray
    eigentextures: np.ndarray
    light_dirs: np.ndarray
    view_dirs: np.ndarray
    channels: tuple[str, ...] = ("R", "G", "B")
    color_model: str = "RGB"
    color_mean: np.ndarray = field(default_factory=lambda: np.zeros(3, np.float32))
    color_matrix: np.ndarray = field(default_factory=lambda: np.eye(3, dtype=np.float32))
    dynamic_range_eps: float = 1e-5

    def __post_init__(self) -> None:
        self.eigen_abrdfs = np.asarray(self.eigen_abrdfs, dtype=np.float32)
        self.singular_values = np.asarray(self.singular_values, dtype=np.float32).reshape(-1)
        self.eigentextures = np.asarray(self.eigentextures, dtype=np.float32)
        self.light_dirs = check_directions(self.light_dirs, "light_dirs")
        self.view_dirs = check_directions(self.view_dirs, "view_dirs")
        self.channels = tuple(str(c) for c in self.channels)
        self.color_mean = np.asarray(self.color_mean, dtype=np.float32).reshape(-1)
        self.color_matrix = np.asarray(self.color_matrix, dtype=np.float32)
        if self.color_model not in COLOR_MODELS:
            raise InputError(f"color_model: {self.color_model!r} is not one of {COLOR_MODELS}")
        if self.eigentextures.ndim != 3 or min(self.eigentextures.shape) < 1:
            raise InputError(
                f"eigentextures: expected (H, W, k) with H, W, k >= 1, got "
                f"{self.eigentextures.shape}"
            )
        if self.color_model != "RGB" and self.n_channels != 3:
            raise InputError(
                f"color_model: {self.color_model!r} needs 3 channels, got {self.n_channels} "
                f"{self.channels} (only RGB may have another count)"
            )
        if self.color_mean.shape != (3,) or self.color_matrix.shape != (3, 3):
            raise InputError(
                f"color_mean, color_matrix: expected (3,) and (3, 3), got "
                f"{self.color_mean.shape}, {self.color_matrix.shape}"
            )
        k = self.eigentextures.shape[2]
        if self.eigen_abrdfs.shape != (self.n_rows, k):
            raise InputError(
                f"eigen_abrdfs: expected ({self.n_rows}, {k}) for {self.n_lights} lights x "
                f"{self.n_views} views x {self.n_channels} channels and k={k}, "
                f"got {self.eigen_abrdfs.shape}"
            )
        if self.singular_values.shape != (k,):
            raise InputError(f"singular_values: expected ({k},), got {self.singular_values.shape}")

    # ----------------------------------------------------------------- layout
    @property
    def n_lights(self) -> int:
        return int(self.light_dirs.shape[0])

    @property
    def n_views(self) -> int:
        return int(self.view_dirs.shape[0])

    @property
    def n_channels(self) -> int:
        return len(self.channels)

    @property
    def n_rows(self) -> int:
        return self.n_lights * self.n_views * self.n_channels

    @property
    def n_components(self) -> int:
        return int(self.eigentextures.shape[2])

    @property
    def shape(self) -> tuple[int, int]:
        """Spatial shape (H, W)."""
        return int(self.eigentextures.shape[0]), int(self.eigentextures.shape[1])

    def rows(self, light: int, view: int) -> np.ndarray:
        """Row indices of the n_channels images at (light, view)."""
        if not 0 <= light < self.n_lights:
            raise InputError(f"light: index {light} outside 0..{self.n_lights - 1}")
        if not 0 <= view < self.n_views:
            raise InputError(f"view: index {view} outside 0..{self.n_views - 1}")
        start = (light * self.n_views + view) * self.n_channels
        return np.arange(start, start + self.n_channels)

    def nearest_light(self, theta: float, phi: float) -> int:
        """Index of the stored light direction closest in angle to (theta, phi) degrees."""
        return _nearest(self.light_dirs, theta, phi)

    def nearest_view(self, theta: float, phi: float) -> int:
        """Index of the stored view direction closest in angle to (theta, phi) degrees."""
        return _nearest(self.view_dirs, theta, phi)

    # ---------------------------------------------------------- decompression
    def image(self, light: int, view: int, *, rgb: bool = True) -> np.ndarray:
        """Decompress the one image at (light, view), (H, W, n_channels) float32.

        Only the n_channels rows of U are used: cost O(H W k n_channels).
        With ``rgb`` the channels are turned into linear RGB (see :meth:`to_rgb`).

        Example
        -------
        >>> img = btf.image(light=0, view=0)  # doctest: +SKIP
        """
        u_rows = self.eigen_abrdfs[self.rows(light, view)]  # (C, k)
        image = self.eigentextures @ u_rows.T  # (H, W, C)
        return self.to_rgb(image) if rgb else image.astype(np.float32)

    def to_rgb(self, values: np.ndarray) -> np.ndarray:
        """Turn values in this BTF's colour model, (..., 3), into linear RGB."""
        values = np.asarray(values, dtype=np.float64)
        if self.color_model == "RGB":
            return values.astype(np.float32)
        eps = self.dynamic_range_eps
        v = values.copy()
        if self.color_model == "YUV":
            out = v @ _YUV_TO_RGB.T
        elif self.color_model == "YCoCg":
            out = v @ _YCOCG_TO_RGB.T
        elif self.color_model == "PCA":
            out = v @ self.color_matrix.astype(np.float64) + self.color_mean
        elif self.color_model == "Ylog_UV":
            v[..., 0] = np.exp(v[..., 0]) - eps
            out = v @ _YUV_TO_RGB.T
        elif self.color_model == "Ylog_Ulog_Vlog":
            v[..., 0] = np.exp(v[..., 0]) - eps
            v[..., 1:] = np.sign(v[..., 1:]) * np.exp(np.abs(v[..., 1:]) + np.log(eps))
            out = v @ _YUV_TO_RGB.T
        elif self.color_model == "Ylog_UdivY_VdivY":
            v[..., 0] = np.exp(v[..., 0]) - eps
            v[..., 1:] *= v[..., :1] + eps
            out = v @ _YUV_TO_RGB.T
        else:  # logRGB
            out = np.exp(v) - eps
        return out.astype(np.float32)

    def matrix(self) -> np.ndarray:
        """The whole decompressed matrix U (V Sigma)^T, (n_rows, H*W). Small BTFs only."""
        flat = self.eigentextures.reshape(-1, self.n_components)
        return (self.eigen_abrdfs @ flat.T).astype(np.float32)

    # -------------------------------------------------------------- new BTFs
    def with_eigentextures(self, eigentextures: np.ndarray) -> BTF:
        """A BTF sharing this one's U, sigma, directions and colours, with new V Sigma.

        Example
        -------
        >>> tiled = np.tile(sample.eigentextures, (4, 4, 1))  # doctest: +SKIP
        >>> big = sample.with_eigentextures(tiled)  # doctest: +SKIP
        """
        eigentextures = np.asarray(eigentextures, dtype=np.float32)
        if eigentextures.ndim != 3 or eigentextures.shape[2] != self.n_components:
            raise InputError(
                f"eigentextures: expected (H, W, {self.n_components}), got {eigentextures.shape}"
            )
        return BTF(
            self.eigen_abrdfs,
            self.singular_values,
            eigentextures,
            self.light_dirs,
            self.view_dirs,
            self.channels,
            self.color_model,
            self.color_mean,
            self.color_matrix,
            self.dynamic_range_eps,
        )

    def crop(self, top: int, left: int, height: int, width: int) -> BTF:
        """The BTF of a rectangle of texels (same U: a crop of a compressed BTF)."""
        h, w = self.shape
        if top < 0 or left < 0 or height < 1 or width < 1 or top + height > h or left + width > w:
            raise InputError(f"crop: rectangle {(top, left, height, width)} outside {h}x{w}")
        return self.with_eigentextures(
            self.eigentextures[top : top + height, left : left + width].copy()
        )

    # ------------------------------------------------------------------- I/O
    def save(self, path: str | os.PathLike) -> Path:
        """Save to one ``.npz`` (atomically)."""
        return write_npz(
            path,
            eigen_abrdfs=self.eigen_abrdfs,
            singular_values=self.singular_values,
            eigentextures=self.eigentextures,
            light_dirs=self.light_dirs,
            view_dirs=self.view_dirs,
            channels=np.array(self.channels),
            color_model=np.array(self.color_model),
            color_mean=self.color_mean,
            color_matrix=self.color_matrix,
            dynamic_range_eps=np.array(self.dynamic_range_eps),
        )

    @classmethod
    def load(cls, path: str | os.PathLike) -> BTF:
        """Load a BTF written by :meth:`save`."""
        path = Path(path)
        fields = read_npz(path, what=".npz BTF")
        required = ("eigen_abrdfs", "singular_values", "eigentextures", "light_dirs", "view_dirs")
        missing = [name for name in required if name not in fields]
        if missing:
            raise InputError(f"{path}: not a BTF file (missing {', '.join(missing)})")
        try:
            return cls(
                fields["eigen_abrdfs"],
                fields["singular_values"],
                fields["eigentextures"],
                fields["light_dirs"],
                fields["view_dirs"],
                tuple(str(c) for c in fields.get("channels", np.array(["R", "G", "B"]))),
                str(fields.get("color_model", "RGB")),
                fields.get("color_mean", np.zeros(3, np.float32)),
                fields.get("color_matrix", np.eye(3, dtype=np.float32)),
                float(fields.get("dynamic_range_eps", 1e-5)),
            )
        except InputError as exc:
            raise InputError(f"{path}: {exc}") from exc


def _nearest(directions: np.ndarray, theta: float, phi: float) -> int:
    vectors = directions_to_vectors(directions)
    target = directions_to_vectors(np.array([[theta, phi]]))[0]
    return int(np.argmax(vectors @ target))


def _gram_tsvd(matrix: np.ndarray, k: int, chunk: int) -> tuple[np.ndarray, np.ndarray]:
    """U and sigma from the eigenvectors of S S^T (rows << columns): exact and cheap."""
    n_rows, n_cols = matrix.shape
    gram = np.zeros((n_rows, n_rows), dtype=np.float64)
    for start in range(0, n_cols, chunk):
        block = matrix[:, start : start + chunk].astype(np.float64)
        gram += block @ block.T
    eigenvalues, eigenvectors = np.linalg.eigh(gram)
    order = np.argsort(eigenvalues)[::-1][:k]
    sigma = np.sqrt(np.clip(eigenvalues[order], 0.0, None))
    return eigenvectors[:, order], sigma


def compress(
    data: np.ndarray,
    *,
    light_dirs: np.ndarray,
    view_dirs: np.ndarray,
    shape: tuple[int, int] | None = None,
    k: int = 100,
    method: str = "auto",
    channels: tuple[str, ...] = ("R", "G", "B"),
    seed: int = 0,
    chunk: int = 65536,
) -> BTF:
    """Compress a BTF by truncated SVD, keeping ``k`` components.

    Parameters
    ----------
    data : ndarray
        Either the matrix S, (n_rows, H*W) with rows in (light, view, channel) C
        order (then give ``shape``), or an image stack (n_lights, n_views, H, W, C).
    light_dirs, view_dirs : array-like, (n, 2)
        (theta, phi) in degrees.
    shape : (H, W), optional
        Spatial shape, required for matrix input.
    k : int
        Components kept (clipped to min(n_rows, H*W)).
    method : {"auto", "gram", "randomized"}
        "gram": eigenvectors of S S^T accumulated in float64 over column chunks
        (exact, memory n_rows^2; for n_rows up to a few thousand). "randomized":
        ``sklearn.utils.extmath.randomized_svd`` (for large row counts). "auto"
        takes "gram" when n_rows <= 4096.
    channels : tuple of str
        Channel names (their count fixes n_channels).
    seed : int
        Seed of the randomized SVD.
    chunk : int
        Columns per block when accumulating S S^T and projecting.

    Returns
    -------
    BTF

    Example
    -------
    >>> btf = compress(S, shape=(64, 64), light_dirs=L, view_dirs=V, k=20)  # doctest: +SKIP
    """
    data = np.asarray(data)
    light_dirs = check_directions(light_dirs, "light_dirs")
    view_dirs = check_directions(view_dirs, "view_dirs")
    n_rows = len(light_dirs) * len(view_dirs) * len(channels)
    if data.ndim == 5:
        if data.shape[:2] != (len(light_dirs), len(view_dirs)) or data.shape[4] != len(channels):
            raise InputError(
                f"data: stack {data.shape} does not match {len(light_dirs)} lights, "
                f"{len(view_dirs)} views, {len(channels)} channels"
            )
        shape = data.shape[2:4]
        matrix = np.ascontiguousarray(np.moveaxis(data, 4, 2), dtype=np.float32).reshape(n_rows, -1)
    elif data.ndim == 2:
        if shape is None:
            raise InputError("shape: required (H, W) when data is a matrix")
        matrix = data if data.dtype == np.float32 else data.astype(np.float32)
        if matrix.shape != (n_rows, shape[0] * shape[1]):
            raise InputError(
                f"data: matrix {matrix.shape} should be ({n_rows}, {shape[0] * shape[1]}) for "
                f"the given directions, channels and shape"
            )
    else:
        raise InputError(f"data: expected a matrix or a 5-D stack, got {data.shape}")
    if not np.all(np.isfinite(matrix)):
        raise InputError("data: has NaN or infinite values")
    k = int(min(k, matrix.shape[0], matrix.shape[1]))
    if k < 1:
        raise InputError("k: must be at least 1")
    if method == "auto":
        method = "gram" if matrix.shape[0] <= 4096 else "randomized"
    if method == "gram":
        u, sigma = _gram_tsvd(matrix, k, chunk)
        flat = np.empty((matrix.shape[1], k), dtype=np.float32)
        u32 = u.astype(np.float32)
        for start in range(0, matrix.shape[1], chunk):
            flat[start : start + chunk] = matrix[:, start : start + chunk].T @ u32
    elif method == "randomized":
        from sklearn.utils.extmath import randomized_svd  # deferred: scikit-learn

        u, sigma, vt = randomized_svd(matrix, k, n_iter=4, random_state=seed)
        flat = (vt.T * sigma).astype(np.float32)
    else:
        raise InputError(f"method: {method!r} is not one of 'auto', 'gram', 'randomized'")
    # Fix the sign of each component (largest |U| entry positive): same data, same factors.
    signs = np.sign(u[np.argmax(np.abs(u), axis=0), np.arange(k)])
    signs[signs == 0] = 1
    u = u * signs
    flat = flat * signs.astype(np.float32)
    return BTF(
        u.astype(np.float32),
        sigma.astype(np.float32),
        flat.reshape(shape[0], shape[1], k),
        light_dirs,
        view_dirs,
        channels,
    )


def relative_error(reference: BTF, reconstruction: BTF, *, decompress: bool = False) -> float:
    """Relative error in percent, e = 100 ||S' - S_rec||_F / ||S'||_F.

    Computed from the factors alone: with W = V Sigma (texels x k) and
    orthonormal U, ||U1 W1^T - U2 W2^T||^2 = ||W1||^2 + ||W2||^2 - 2 <W1 U1^T U2, W2>,
    which needs only the k1 x k2 matrix U1^T U2 (the identity when U is shared)
    and never forms S. ``decompress=True`` forms both matrices instead (small
    BTFs; for tests).

    Parameters
    ----------
    reference, reconstruction : BTF
        Same directions, channels and spatial shape.

    Returns
    -------
    float
        Percent.

    Example
    -------
    >>> relative_error(reference, tiled)  # doctest: +SKIP
    41.3
    """
    if reference.shape != reconstruction.shape:
        raise InputError(
            f"reconstruction: shape {reconstruction.shape} differs from the reference's "
            f"{reference.shape}"
        )
    if reference.n_rows != reconstruction.n_rows:
        raise InputError(
            f"reconstruction: {reconstruction.n_rows} rows, the reference has {reference.n_rows}"
        )
    if decompress:
        s_ref = reference.matrix().astype(np.float64)
        s_rec = reconstruction.matrix().astype(np.float64)
        return float(100.0 * np.linalg.norm(s_ref - s_rec) / np.linalg.norm(s_ref))
    w1 = reference.eigentextures.reshape(-1, reference.n_components).astype(np.float64)
    w2 = reconstruction.eigentextures.reshape(-1, reconstruction.n_components).astype(np.float64)
    if reference.eigen_abrdfs is reconstruction.eigen_abrdfs:
        cross = np.einsum("ij,ij->", w1, w2)
    else:
        gram = reference.eigen_abrdfs.astype(np.float64).T @ reconstruction.eigen_abrdfs.astype(
            np.float64
        )
        cross = np.einsum("ij,ij->", w1 @ gram, w2)
    norm_ref = np.einsum("ij,ij->", w1, w1)
    norm_rec = np.einsum("ij,ij->", w2, w2)
    squared = max(norm_ref + norm_rec - 2.0 * cross, 0.0)
    return float(100.0 * np.sqrt(squared) / np.sqrt(norm_ref))
