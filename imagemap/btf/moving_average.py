"""The moving-average BTF model (Havlicek & Haindl, papers/moving-average-btf-model.txt).

One module for one job: one model, its fit, file, synthesis and size (signals: ``ma_signal``).

A parametric, stochastic alternative to example-based BTF enlargement:

1. range map of the material by over-determined photometric stereo on the top view
   (:mod:`imagemap.btf.photometric`), enlarged by seamless periodic tiling (section 2.1);
2. optional segmentation of the BTF images into subspaces by K-means in CIELAB; one
   representative image (the member nearest the centroid) is modelled per subspace;
3. spectral decorrelation of a representative by the Karhunen-Loeve transform (2.2) and
   spatial factorization of each decorrelated band by a Gaussian-Laplacian pyramid (2.3);
4. per mono-spectral band-limited factor, a 2D moving-average (MA) kernel estimated by the
   random-decrement procedure (2.5): threshold gamma = 0.5 sigma, a window is kept where the
   factor crosses gamma (the pixel is >= gamma while at least one of its row neighbours and
   one of its column neighbours are below), the summed windows are divided by their count;
5. synthesis of any size by convolving white noise with each kernel (2.6, circular FFT
   convolution, so the result tiles seamlessly), inverse K-L and pyramid collapse;
6. appearance under any light and view: the synthetic smooth texture of the subspace of the
   nearest measured (light, view) pair, bump mapped with the enlarged range map.

By default the averaged windows are the filter, as the paper states (``kernel="signature"``,
scaled so the filter's energy equals the factor's variance). For a Gaussian field the
random-decrement average is, in theory, proportional to the autocorrelation R(s), whose
convolution with white noise would be too smooth; ``kernel="spectral_root"`` instead takes
the zero-phase filter whose autocorrelation is the signature. Measured on MA fields of known
Gaussian kernels, the crossing condition (neighbours below gamma) sharpens the average so
much that the plain signature reproduces the field's autocorrelation better (lags 1-3 within
0.05, against up to 0.2 too low for the spectral root), so the paper's choice is the default.
The bump mapping divides the representative
image by its own range-map shading before modelling (``deshade``), so the shading is not
counted twice; the synthetic texture is shaded again with the enlarged range map.

The signal blocks (K-L transform, random decrement, kernels, band synthesis,
segmentation) live in :mod:`imagemap.btf.ma_signal`; this module fits and uses the model.
"""

from __future__ import annotations

import ast
import hashlib
import os
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from imagemap.btf.ma_signal import (  # noqa: F401 - re-exported, and _expand_wrap for tests
    _expand_wrap,
    _lab_features,
    collapse_periodic,
    inverse_karhunen_loeve,
    karhunen_loeve,
    ma_kernel_from_signature,
    random_decrement_signature,
    segment_subspaces,
    synthesize_band,
)
from imagemap.btf.photometric import (
    btf_direction_vectors,
    crossfade_tile,
    enlarge_range_map,
    flat_where_left_out,
    frankot_chellappa,
    photometric_stereo,
)
from imagemap.core.pyramid import laplacian_pyramid, level_shapes
from imagemap.io import InputError, read_npz, write_npz
from imagemap.render import normals_from_height

__all__ = [
    "MIN_COARSE_SIDE",
    "MAParams",
    "MovingAverageModel",
    "collapse_periodic",
    "compression_ratios",
    "experiment_method",
    "fit_moving_average",
    "fit_moving_average_btf",
    "inverse_karhunen_loeve",
    "karhunen_loeve",
    "max_levels",
    "ma_kernel_from_signature",
    "moving_average_extrapolate",
    "parameter_count",
    "random_decrement_signature",
    "sample_fingerprint",
    "segment_subspaces",
    "synthesis_bytes",
    "synthesize_band",
    "synthesize_btf",
    "synthesize_appearance",
    "synthesize_smooth_textures",
]


@dataclass(frozen=True)
class MAParams:
    """Parameters of the moving-average BTF model.

    Parameters
    ----------
    levels : int
        Gaussian-Laplacian pyramid levels (the paper: 4 for 128 x 128).
    support : int
        Odd width of the square MA kernel support I_r (shrunk on small coarse levels).
    threshold : float
        Random-decrement threshold gamma in units of the factor's standard deviation.
    kernel : {"spectral_root", "signature"}
        How the averaged windows become the filter (see the module docstring).
    n_subspaces : int
        K-means clusters of BTF images; 1 models one representative for the whole BTF.
    deshade : bool
        Divide representatives by their range-map shading before modelling.
    bump_scale : float
        Multiplier of the range map's heights when bump mapping.
    min_intensity : float
        Photometric stereo: samples darker than this are treated as shadowed.
    """

    levels: int = 4
    support: int = 13
    threshold: float = 0.5
    kernel: str = "signature"
    n_subspaces: int = 8
    deshade: bool = True
    bump_scale: float = 1.0
    min_intensity: float = 0.0

    def __post_init__(self) -> None:
        for name in ("levels", "support", "n_subspaces"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | np.integer):
                raise InputError(f"{name}: an integer, got {value!r}")
        if self.levels < 1:
            raise InputError(f"levels: must be at least 1, got {self.levels}")
        if self.support < 1 or self.support % 2 == 0:
            raise InputError(f"support: must be a positive odd width, got {self.support}")
        if not (np.isfinite(self.threshold) and self.threshold >= 0):
            raise InputError(f"threshold: must be finite and >= 0 (in sigma), got {self.threshold}")
        if not (np.isfinite(self.bump_scale) and self.bump_scale >= 0):
            raise InputError(f"bump_scale: a finite height multiplier >= 0, got {self.bump_scale}")
        if not np.isfinite(self.min_intensity):
            raise InputError(f"min_intensity: must be finite, got {self.min_intensity}")
        if self.kernel not in ("spectral_root", "signature"):
            raise InputError(
                f"kernel: expected 'spectral_root' or 'signature', got {self.kernel!r}"
            )
        if self.n_subspaces < 1:
            raise InputError(f"n_subspaces: must be at least 1, got {self.n_subspaces}")


#: Coarsest pyramid level's shorter side at least (texels): its MA kernel is then at least
#: 3 x 3 (a third of the side, see _fit_representative); at 4 texels it is 1 x 1, white noise.
MIN_COARSE_SIDE = 8

#: Format tag of a saved model.
MODEL_FORMAT = "imagemap-moving-average-btf-1"


def max_levels(shape: tuple[int, int]) -> int:
    """The most pyramid levels a sample of ``shape`` supports (coarsest side >= 8).

    Example
    -------
    >>> max_levels((16, 16)), max_levels((128, 100))
    (2, 4)
    """
    side = min(int(shape[0]), int(shape[1]))
    return max(1, 1 + int(np.floor(np.log2(max(side, 1) / MIN_COARSE_SIDE))))


def sample_fingerprint(btf) -> str:
    """A digest of a BTF's eigen-ABRDFs, directions and channels: what a model fitted on it
    must be synthesized with (:func:`synthesize_btf` projects onto that U).

    Example
    -------
    >>> from imagemap.btf import BTF
    >>> btf = BTF(np.eye(3)[:, :1], [1.0], np.ones((2, 2, 1)), [[0, 0]], [[0, 0]])
    >>> len(sample_fingerprint(btf))
    16
    """
    digest = hashlib.sha256()
    for array in (btf.eigen_abrdfs, btf.light_dirs, btf.view_dirs):
        digest.update(np.ascontiguousarray(array, dtype=np.float32).tobytes())
    digest.update(repr((btf.channels, btf.color_model)).encode())
    return digest.hexdigest()[:16]


# --------------------------------------------------------------------------------- the model
@dataclass
class MovingAverageModel:
    """A fitted moving-average BTF model (all arrays; saved to one ``.npz``).

    Attributes
    ----------
    kernels : list (per subspace) of list (per level) of ndarray (C, s_l, s_l)
        MA filters of the K-L bands at each pyramid level (finest first).
    level_means : ndarray (K, L, C)
        Mean of each band-limited factor (the MA field itself is zero-mean).
    kl_means, kl_bases : ndarray (K, C), (K, C, C)
        Inverse K-L transform of each subspace.
    subspace_of : ndarray (n_lights, n_views) int
        Subspace of every measured (light, view) pair.
    light_vectors, view_vectors : ndarray (n_lights, 3), (n_views, 3)
        Unit directions, z up.
    range_map : ndarray (h, w)
        Periodic range-map tile in pixels (:func:`imagemap.btf.photometric.crossfade_tile`
        of the photometric-stereo heights), enlarged by tiling.
    sample_shape : (int, int)
    params : MAParams
    sample_digest : str
        :func:`sample_fingerprint` of the BTF it was fitted on ("" for plain images).
    """

    kernels: list
    level_means: np.ndarray
    kl_means: np.ndarray
    kl_bases: np.ndarray
    subspace_of: np.ndarray
    light_vectors: np.ndarray
    view_vectors: np.ndarray
    range_map: np.ndarray
    sample_shape: tuple[int, int]
    params: MAParams = field(default_factory=MAParams)
    sample_digest: str = ""

    @property
    def n_subspaces(self) -> int:
        return int(self.kl_means.shape[0])

    def save(self, path: str | os.PathLike) -> Path:
        """Write the model to one ``.npz`` atomically."""
        arrays = {
            f"kernel_{k}_{level}": self.kernels[k][level]
            for k in range(self.n_subspaces)
            for level in range(len(self.kernels[k]))
        }
        return write_npz(
            path,
            level_means=self.level_means,
            kl_means=self.kl_means,
            kl_bases=self.kl_bases,
            subspace_of=self.subspace_of,
            light_vectors=self.light_vectors,
            view_vectors=self.view_vectors,
            range_map=self.range_map,
            sample_shape=np.array(self.sample_shape),
            params=np.array(repr(asdict(self.params))),
            sample_digest=np.array(self.sample_digest),
            format=np.array(MODEL_FORMAT),
            **arrays,
        )

    @classmethod
    def load(cls, path: str | os.PathLike) -> MovingAverageModel:
        """Read a model written by :meth:`save`."""
        path = Path(path)
        fields = read_npz(path)
        if str(fields.get("format", "")) != MODEL_FORMAT:
            raise InputError(f"{path}: not a moving-average BTF model (see 'imagemap btf ma-fit')")
        try:
            k_count, levels = fields["level_means"].shape[:2]
            kernels = [[fields[f"kernel_{k}_{lv}"] for lv in range(levels)] for k in range(k_count)]
            model = cls(
                kernels,
                fields["level_means"],
                fields["kl_means"],
                fields["kl_bases"],
                fields["subspace_of"],
                fields["light_vectors"],
                fields["view_vectors"],
                fields["range_map"],
                (int(fields["sample_shape"][0]), int(fields["sample_shape"][1])),
                MAParams(**ast.literal_eval(str(fields["params"]))),
                str(fields.get("sample_digest", "")),
            )
        except InputError as exc:
            raise InputError(f"{path}: {exc}") from None
        except (KeyError, ValueError, TypeError, SyntaxError, IndexError) as exc:
            raise InputError(f"{path}: damaged moving-average model ({exc!r})") from None
        arrays = [model.level_means, model.kl_means, model.kl_bases, model.range_map]
        arrays += [k for per_k in model.kernels for k in per_k]
        if not all(np.all(np.isfinite(a)) for a in arrays):
            raise InputError(f"{path}: damaged moving-average model (NaN or infinite values)")
        return model


def _bump_factor(normals: np.ndarray, light: np.ndarray, *, floor: float = 0.0) -> np.ndarray:
    """Lambert shading of the bumped surface relative to its mean under the same light."""
    shading = np.clip(normals @ np.asarray(light, np.float32), 0.0, None)
    mean = float(shading.mean())
    if mean <= 1e-6:
        return np.zeros(normals.shape[:2], np.float32)
    return np.maximum(shading / mean, floor).astype(np.float32)


def _fit_representative(image: np.ndarray, params: MAParams):
    """K-L, pyramid and one MA kernel per mono-spectral band-limited factor."""
    bands, kl_mean, kl_basis = karhunen_loeve(image)
    pyramid = laplacian_pyramid(bands, params.levels)
    kernels, means = [], []
    for level in pyramid:
        smallest = min(level.shape[:2])
        # A window must leave room for crossings inside small coarse levels.
        support = int(min(params.support, max(1, (smallest // 3) | 1)))
        level_kernels, level_means = [], []
        for channel in range(level.shape[2]):
            factor = level[..., channel].astype(np.float64)
            signature, _ = random_decrement_signature(
                factor, support=support, threshold=params.threshold
            )
            level_kernels.append(
                ma_kernel_from_signature(signature, float(factor.var()), kernel=params.kernel)
            )
            level_means.append(float(factor.mean()))
        kernels.append(np.stack(level_kernels))
        means.append(level_means)
    return kernels, np.array(means, np.float32), kl_mean, kl_basis


def fit_moving_average(
    images: np.ndarray | None,
    light_vectors: np.ndarray,
    view_vectors: np.ndarray,
    *,
    params: MAParams | None = None,
    seed: int = 0,
    image_of=None,
) -> MovingAverageModel:
    """Fit the moving-average BTF model to measured images (plain arrays).

    Parameters
    ----------
    images : ndarray (n_lights, n_views, H, W, 3), or None with ``image_of``
        Linear RGB BTF images.
    light_vectors, view_vectors : ndarray (n_lights, 3), (n_views, 3)
        Unit directions, z up, in the image frame of :mod:`imagemap.render`.
    params : MAParams, optional
    seed : int
        Seed of the K-means initialization.
    image_of : callable (light, view) -> (H, W, 3), optional
        Fetches one image at a time instead of ``images`` (large BTFs).

    Returns
    -------
    MovingAverageModel

    Examples
    --------
    >>> model = fit_moving_average(stack, lights, views)  # doctest: +SKIP
    """
    params = params or MAParams()
    lights = np.asarray(light_vectors, np.float64)
    views = np.asarray(view_vectors, np.float64)
    if lights.ndim != 2 or lights.shape[1] != 3 or views.ndim != 2 or views.shape[1] != 3:
        raise InputError("light_vectors, view_vectors: expected (n, 3) unit vectors")
    lights /= np.linalg.norm(lights, axis=1, keepdims=True)
    views /= np.linalg.norm(views, axis=1, keepdims=True)
    n_lights, n_views = len(lights), len(views)
    if image_of is None:
        images = np.asarray(images, dtype=np.float32)
        if images.ndim != 5 or images.shape[:2] != (n_lights, n_views) or images.shape[4] != 3:
            raise InputError(
                f"images: expected ({n_lights}, {n_views}, H, W, 3), got {np.shape(images)}"
            )
        if not np.all(np.isfinite(images)):
            raise InputError("images: have NaN or infinite values")

        def image_of(light: int, view: int) -> np.ndarray:
            return images[light, view]

    top_view = int(np.argmax(views[:, 2]))
    top_stack = np.stack([image_of(light, top_view) for light in range(n_lights)])
    sample_shape = top_stack.shape[1:3]
    if params.levels > max_levels(sample_shape):
        raise InputError(
            f"levels: {params.levels} pyramid levels need a sample of at least "
            f"{MIN_COARSE_SIDE * 2 ** (params.levels - 1)} texels on its shorter side; this "
            f"one is {sample_shape[0]}x{sample_shape[1]} (at most {max_levels(sample_shape)})"
        )
    normals, _ = photometric_stereo(top_stack, lights, min_intensity=params.min_intensity)
    normals = flat_where_left_out(normals)  # the range map is the whole sample's
    sample_height = frankot_chellappa(normals)
    # Deshading needs the heights registered with the sample; synthesis needs a tile.
    bumped = normals_from_height(sample_height, scale=params.bump_scale)
    range_map = crossfade_tile(sample_height)

    scale = float(np.percentile(top_stack, 99.5)) or 1.0
    features = np.array(
        [_lab_features(image_of(lt, vw), scale) for lt in range(n_lights) for vw in range(n_views)]
    )
    labels, representatives = segment_subspaces(features, params.n_subspaces, seed=seed)

    kernels, level_means, kl_means, kl_bases = [], [], [], []
    for index in representatives:
        light, view = divmod(int(index), n_views)
        image = image_of(light, view).astype(np.float32)
        if params.deshade:
            image = image / np.maximum(_bump_factor(bumped, lights[light]), 0.25)[..., None]
        k_kernels, k_means, k_mean, k_basis = _fit_representative(image, params)
        kernels.append(k_kernels)
        level_means.append(k_means)
        kl_means.append(k_mean)
        kl_bases.append(k_basis)
    return MovingAverageModel(
        kernels=kernels,
        level_means=np.stack(level_means),
        kl_means=np.stack(kl_means),
        kl_bases=np.stack(kl_bases),
        subspace_of=labels.reshape(n_lights, n_views),
        light_vectors=lights.astype(np.float32),
        view_vectors=views.astype(np.float32),
        range_map=range_map.astype(np.float32),
        sample_shape=(int(sample_shape[0]), int(sample_shape[1])),
        params=params,
    )


def fit_moving_average_btf(
    btf, *, params: MAParams | None = None, seed: int = 0
) -> MovingAverageModel:
    """Fit the model to an :class:`imagemap.btf.BTF`, decompressing one image at a time.

    Examples
    --------
    >>> model = fit_moving_average_btf(BTF.load("sample.npz"))  # doctest: +SKIP
    """
    model = fit_moving_average(
        None,
        btf_direction_vectors(btf.light_dirs),
        btf_direction_vectors(btf.view_dirs),
        params=params,
        seed=seed,
        image_of=lambda light, view: btf.image(light, view),
    )
    model.sample_digest = sample_fingerprint(btf)
    return model


def synthesize_smooth_textures(
    model: MovingAverageModel, shape: tuple[int, int], *, seed: int = 0
) -> np.ndarray:
    """Synthetic smooth multi-spectral texture of every subspace, any size, seamless.

    All subspaces share the same white-noise fields (one per level and K-L band), so their
    textures are spatially coherent: a texel keeps its character from light to light.

    Returns
    -------
    textures : ndarray (K, H, W, 3) float32

    Examples
    --------
    >>> textures = synthesize_smooth_textures(model, (512, 512), seed=1)  # doctest: +SKIP
    """
    height, width = (int(s) for s in shape)
    if height < 1 or width < 1:
        raise InputError(f"shape: must be positive, got {shape}")
    rng = np.random.default_rng(seed)
    levels = len(model.kernels[0])
    channels = model.kl_means.shape[1]
    shapes = level_shapes((height, width), levels)
    noise = [[rng.standard_normal(s) for _ in range(channels)] for s in shapes]
    textures = np.empty((model.n_subspaces, height, width, channels), np.float32)
    for k in range(model.n_subspaces):
        pyramid = [
            np.stack(
                [
                    synthesize_band(model.kernels[k][lv][c], shapes[lv], noise=noise[lv][c])
                    + model.level_means[k, lv, c]
                    for c in range(channels)
                ],
                axis=-1,
            )
            for lv in range(levels)
        ]
        bands = np.stack(
            [collapse_periodic([p[..., c] for p in pyramid]) for c in range(channels)], -1
        )
        textures[k] = inverse_karhunen_loeve(bands, model.kl_means[k], model.kl_bases[k])
    return textures


def _enlarged_normals(model: MovingAverageModel, shape, seed: int) -> np.ndarray:
    # One extra texel of the tiling on each side: central differences everywhere, and no
    # false wrap-around slope when the size is not a multiple of the tile.
    padded = (int(shape[0]) + 2, int(shape[1]) + 2)
    height = enlarge_range_map(model.range_map, padded, method="wrap", seed=seed)
    return normals_from_height(height, scale=model.params.bump_scale)[1:-1, 1:-1]


def synthesize_appearance(
    model: MovingAverageModel,
    light: np.ndarray,
    view: np.ndarray,
    shape: tuple[int, int],
    *,
    seed: int = 0,
    textures: np.ndarray | None = None,
) -> np.ndarray:
    """The enlarged material under any light and view: smooth texture x bump shading.

    The subspace is that of the measured (light, view) pair nearest to the request (sum of
    the two cosines); the texture is shaded with the enlarged range map under ``light``
    relative to a flat average, so the mean brightness stays that of the subspace.

    Parameters
    ----------
    model : MovingAverageModel
    light, view : 3-vectors
        Unit directions, z up.
    shape : (H, W)
    seed : int
        Seed of the noise fields and of the range-map tiling offset.
    textures : ndarray (K, H, W, 3), optional
        Precomputed :func:`synthesize_smooth_textures` (same seed and shape).

    Returns
    -------
    image : ndarray (H, W, 3) float32, linear (not clipped)
    """
    light = np.asarray(light, np.float64) / np.linalg.norm(light)
    view = np.asarray(view, np.float64) / np.linalg.norm(view)
    best_light = int(np.argmax(model.light_vectors @ light))
    best_view = int(np.argmax(model.view_vectors @ view))
    subspace = int(model.subspace_of[best_light, best_view])
    if textures is None:
        textures = synthesize_smooth_textures(model, shape, seed=seed)
    normals = _enlarged_normals(model, shape, seed)
    return (textures[subspace] * _bump_factor(normals, light)[..., None]).astype(np.float32)


def synthesize_btf(model: MovingAverageModel, sample, shape: tuple[int, int], *, seed: int = 0):
    """Synthesize the enlarged BTF on the sample's eigen-ABRDFs: V Sigma = S'^T U.

    Every rendered row image (light, view, channel) is projected onto the sample's U, so the
    result is a :class:`imagemap.btf.BTF` sharing U and the relative error is computed the
    same way as for the example-based methods. The projection is grouped by subspace and
    channel so it runs as a few large matrix products: with F the (texels, lights) matrix of
    bump factors, V Sigma = sum_k sum_c T_kc * (F @ U_kc), U_kc summing the U rows of the
    (light, view) pairs of subspace k.

    Parameters
    ----------
    model : MovingAverageModel
    sample : imagemap.btf.BTF
        Gives U, directions and channels (RGB colour model expected).
    shape : (H, W)
    seed : int

    Returns
    -------
    imagemap.btf.BTF
    """
    if sample.n_channels != 3 or sample.color_model != "RGB":
        raise InputError("sample: the moving-average model needs an RGB BTF")
    if model.subspace_of.shape != (sample.n_lights, sample.n_views):
        raise InputError(
            f"model: fitted on {model.subspace_of.shape} (lights, views), sample has "
            f"{(sample.n_lights, sample.n_views)}"
        )
    if model.sample_digest and model.sample_digest != sample_fingerprint(sample):
        raise InputError(
            "sample: not the BTF the model was fitted on (its eigen-ABRDFs, directions or "
            "channels differ): the synthesized textures would be projected onto another "
            "material's U"
        )
    height, width = (int(s) for s in shape)
    textures = synthesize_smooth_textures(model, (height, width), seed=seed)
    normals = _enlarged_normals(model, (height, width), seed)
    factors = np.stack(
        [_bump_factor(normals, light).reshape(-1) for light in model.light_vectors], axis=1
    )  # (texels, lights)
    u = sample.eigen_abrdfs.reshape(sample.n_lights, sample.n_views, 3, -1)
    eigentextures = np.zeros((height * width, sample.n_components), np.float32)
    for k in range(model.n_subspaces):
        in_subspace = (model.subspace_of == k).astype(np.float32)  # (lights, views)
        u_k = np.einsum("lv,lvcj->lcj", in_subspace, u)  # (lights, C, k)
        for channel in range(3):
            projected = factors @ u_k[:, channel, :]
            eigentextures += textures[k, ..., channel].reshape(-1, 1) * projected
    return sample.with_eigentextures(eigentextures.reshape(height, width, -1))


def moving_average_extrapolate(
    sample, output_shape: tuple[int, int], *, seed: int = 0, params: MAParams | None = None
):
    """The ``moving_average`` row of ``imagemap btf experiment``: fit on the sample, enlarge.

    Parameters
    ----------
    sample : imagemap.btf.BTF
        The measured cut-out.
    output_shape : (H, W)
    seed : int
    params : MAParams, optional

    Returns
    -------
    imagemap.btf.BTF
        Shares the sample's U, so :func:`imagemap.btf.relative_error` applies directly.

    Examples
    --------
    >>> big = moving_average_extrapolate(sample, (512, 512), seed=0)  # doctest: +SKIP
    """
    model = fit_moving_average_btf(sample, params=params, seed=seed)
    return synthesize_btf(model, sample, output_shape, seed=seed)


# ------------------------------------------------------------------------ memory
#: Bytes per output texel that do not depend on the model: the finest level's FFT
#: convolution (complex128 spectrum, kernel spectrum and product: 48) and the enlarged
#: range map with its float64 gradients and float32 normals (about 60). With it the
#: estimate is 1.18x the measured peak (tracemalloc) of an image and 1.35x that of a BTF
#: (256^2 and 512^2, 4 subspaces, k = 24, 6 lights x 2 views): a margin, never short.
_TEXEL_BYTES = 110


def synthesis_bytes(
    model: MovingAverageModel, shape: tuple[int, int], *, n_components: int | None = None
) -> int:
    """Estimated peak bytes of :func:`synthesize_appearance` (``n_components`` None) or of
    :func:`synthesize_btf` onto a sample with ``n_components`` eigentextures.

    Per texel: the white noise of every level and band (float64, 4/3 of the finest level),
    every subspace's smooth texture (float32), the FFT work and the range map; for a BTF
    also the bump factors of every light and the eigentextures with their products.

    Example
    -------
    >>> model = MovingAverageModel([[np.ones((3, 1, 1))]], np.zeros((1, 1, 3)), np.zeros((1, 3)),
    ...     np.eye(3)[None], np.zeros((1, 1), int), np.eye(3)[2:], np.eye(3)[2:],
    ...     np.zeros((4, 4)), (4, 4))
    >>> synthesis_bytes(model, (1000, 1000)) > 100 * 10**6
    True
    """
    texels = float(shape[0]) * float(shape[1])
    channels = model.kl_means.shape[1]
    per_texel = 8 * channels * 4 / 3 + 4 * model.n_subspaces * channels + _TEXEL_BYTES
    if n_components is None:
        per_texel += 4 * channels  # the shaded image
    else:
        per_texel += 4 * len(model.light_vectors) + 3 * 4 * n_components
    return int(per_texel * texels)


# ------------------------------------------------------------------------ size and compression
def parameter_count(model: MovingAverageModel) -> dict[str, int]:
    """Numbers the model stores, by part.

    Returns
    -------
    dict with "kernels", "band_means", "kl", "range_map", "subspace_map", "directions",
    "total".
    """
    counts = {
        "kernels": int(sum(k.size for per_k in model.kernels for k in per_k)),
        "band_means": int(model.level_means.size),
        "kl": int(model.kl_means.size + model.kl_bases.size),
        "range_map": int(model.range_map.size),
        "subspace_map": int(model.subspace_of.size),
        "directions": int(2 * (len(model.light_vectors) + len(model.view_vectors))),
    }
    counts["total"] = int(sum(counts.values()))
    return counts


def compression_ratios(
    model: MovingAverageModel, shape: tuple[int, int], *, tsvd_rank: int = 100
) -> dict[str, float]:
    """Compression of the model against raw and TSVD data of a BTF of ``shape`` texels.

    Raw: n_lights * n_views * 3 values per texel. TSVD (rank k): U (rows x k), sigma (k)
    and V Sigma (texels x k). The model's size does not grow with ``shape``.

    Examples
    --------
    >>> compression_ratios(model, (512, 512))["vs_raw"]  # doctest: +SKIP
    """
    n_rows = model.subspace_of.size * 3
    texels = int(shape[0]) * int(shape[1])
    raw = n_rows * texels
    k = min(tsvd_rank, n_rows, texels)
    tsvd = k * (n_rows + texels + 1)
    total = parameter_count(model)["total"]
    return {
        "raw_values": float(raw),
        "tsvd_values": float(tsvd),
        "model_values": float(total),
        "vs_raw": raw / total,
        "vs_tsvd": tsvd / total,
    }


def experiment_method(sample, shape: tuple[int, int], seed: int = 0):
    """Hook of :mod:`imagemap.btf.experiment` (``moving_average`` row), default parameters.

    Same as ``moving_average_extrapolate(sample, shape, seed=seed)``, with no more pyramid
    levels than the sample supports (:func:`max_levels`; the default 4 from 64 texels).
    """
    levels = min(MAParams().levels, max_levels(sample.shape))
    return moving_average_extrapolate(sample, shape, seed=seed, params=MAParams(levels=levels))
