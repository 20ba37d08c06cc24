"""Read the University of Bonn UBO2014 BTFs (DFMF: decorrelated full matrix factorization).

The layout follows the public Bonn parsers: btflib (github.com/cgbonn/btflib,
matlab/@btf/private/read_ubo_dfmf.m, read_meta_data.m, read_bidir_sampling.m,
decode_dfmf_texture.m, undecorrelate.m) and pysmtb's ``read_ubo_btf_dfmf``.
All numbers little-endian::

    "!DFMF08FCR"                               10-byte signature
    meta block: uint32 size (bytes, counting this field), uint32 version,
        char[80] measurement setup, char[80] image sensor, char[80] light source,
        float32 ppmm, float32[3] rgb scale factor,
        version > 1: uint32 cosine flag; version > 2: uint32 n + char[n] XML;
        version > 3: uint32 channels, then per channel uint32 n + char[n] name
    uint32 n_views; per view: float32 theta, phi (radians),
        uint32 n_lights, float32[n_lights][2] (theta, phi)
    uint32 width, uint32 height
    signature ends in "R": uint32 n_rotations, float32[n_rotations][3][3]
    uint32 components, int32 colour model, float32[3] colour mean,
        float32[3][3] colour transformation
    per channel: uint8 scalar size (2, 4, 8 -> float16/32/64), uint32 k,
        uint32 rows, uint32 cols, S[k], U[rows][k], SxV[cols][k] (row-major)

U's rows are (view, light) pairs, the light index fastest (row = v * n_lights + l);
SxV's rows are texels, x fastest (texel = y * width + x). Each decorrelated
channel has its own factorization; :func:`read_ubo2014` places them in one BTF
with a block-diagonal U (still orthonormal) and the channel's colour model, so
decompression and the compressed-domain error work unchanged.

Some files store the transposed factorization ("images" layout): rows = texels and
cols = direction pairs, U holding the texels' factor and SxV the ABRDFs' times sigma.
The file has no field naming the layout: readers tell it from rows and cols. When
width * height equals n_views * n_lights the two layouts have the same sizes and a
reader takes the normal one (as btflib does), so :func:`write_ubo2014` refuses the
images layout for such sizes instead of writing a file every reader misreads.

Values are range-checked: a factor that float16 (``scalar_size`` 2) cannot hold
(|value| > 65504) is refused by the writer, and so is a channel it would flush to zero
(every component below float16's 6e-8; some components lost are warned about); the reader
refuses NaN or infinite values (factors, colour mean and transformation), zero sizes, a
components field that is neither the channels' largest k (btflib writes that) nor their
sum, bytes after the last channel, a colour model other than RGB on anything but three
channels (the decorrelated models are 3-channel transforms) and directions outside the
upper hemisphere, naming the field and the channel.
"""

from __future__ import annotations

import logging
import os
import struct
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from imagemap.btf.core import BTF, check_directions
from imagemap.io import InputError, atomic_path
from imagemap.outputs import check_writable

__all__ = ["SIGNATURE", "COLOR_MODEL_CODES", "read_ubo2014", "write_ubo2014"]

SIGNATURE = b"!DFMF08FCR"

log = logging.getLogger("imagemap")

#: btflib's colour model numbers -> our names (2 LAB and 5/6 spectral are not supported).
COLOR_MODEL_CODES = {
    0: "RGB",
    1: "YUV",
    3: "PCA",
    4: "YCoCg",
    9: "Ylog_UV",
    10: "Ylog_Ulog_Vlog",
    11: "Ylog_UdivY_VdivY",
    12: "logRGB",
}
_SCALAR_TYPES = {2: np.float16, 4: np.float32, 8: np.float64}
#: The largest finite value of each scalar type (float16: 65504).
_SCALAR_LIMITS = {
    2: 65504.0,
    4: float(np.finfo(np.float32).max),
    8: float(np.finfo(np.float64).max),
}

#: Meta-block versions the format description above covers (btflib writes 1 to 4).
META_VERSIONS = (1, 2, 3, 4)


class _Reader:
    def __init__(self, data: bytes, path: Path) -> None:
        self.data, self.pos, self.path = data, 0, path

    def take(self, n: int) -> bytes:
        if self.pos + n > len(self.data):
            raise InputError(f"{self.path}: truncated DFMF file (needs {self.pos + n} bytes)")
        chunk = self.data[self.pos : self.pos + n]
        self.pos += n
        return chunk

    def scalars(self, fmt: str, count: int = 1):
        values = struct.unpack("<" + fmt * count, self.take(struct.calcsize("<" + fmt) * count))
        return values if count > 1 else values[0]

    def array(self, dtype, count: int) -> np.ndarray:
        dtype = np.dtype(dtype).newbyteorder("<")
        return np.frombuffer(self.take(dtype.itemsize * count), dtype=dtype, count=count)


def read_ubo2014(path: str | os.PathLike) -> BTF:
    """Read a Bonn DFMF ``.btf`` file into a :class:`~imagemap.btf.BTF`.

    Parameters
    ----------
    path : str or path-like

    Returns
    -------
    BTF
        U block-diagonal over the channels (k = sum of the channels' components),
        eigentextures (height, width, k), directions in degrees, the file's colour
        model (``BTF.image`` returns linear RGB).

    Raises
    ------
    InputError
        Not a DFMF file, truncated, or an unsupported colour model.

    Example
    -------
    >>> import tempfile
    >>> path = Path(tempfile.mkdtemp()) / "grey.btf"
    >>> _ = write_ubo2014(path, eigen_abrdfs=[np.eye(2)], singular_values=[[2.0, 1.0]],
    ...                   eigentextures=[np.ones((2, 3, 2))], channels=("L",),
    ...                   light_dirs=[[0, 0], [45, 90]], view_dirs=[[0, 0]])
    >>> btf = read_ubo2014(path)
    >>> btf.shape, btf.n_lights, btf.light_dirs[1].round(3).tolist()
    ((2, 3), 2, [45.0, 90.0])
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: file not found")
    f = _Reader(path.read_bytes(), path)
    signature = f.take(len(SIGNATURE))
    if signature != SIGNATURE:
        raise InputError(f"{path}: not a Bonn DFMF BTF (signature {signature!r})")
    start = f.pos
    size, version = f.scalars("I"), f.scalars("I")
    if version not in META_VERSIONS:
        raise InputError(f"{path}: meta block version {version} is not one of {META_VERSIONS}")
    f.take(240)  # measurement setup, image sensor, light source descriptions
    f.scalars("f", 4)  # pixels per mm, RGB scale factors
    if version > 1:
        f.scalars("I")  # cosine already multiplied into the data
    if version > 2:
        f.take(f.scalars("I"))  # XML measurement description
    channels = ["R", "G", "B"]
    if version > 3:
        n_channels = f.scalars("I")
        if n_channels < 1:
            raise InputError(f"{path}: channels: the meta block lists none")
        channels = [f.take(f.scalars("I")).decode("latin-1").strip("\0") for _ in range(n_channels)]
    if f.pos - start != size:
        raise InputError(f"{path}: meta block is {f.pos - start} bytes, header says {size}")
    n_views = f.scalars("I")
    views, lights = [], None
    for view in range(n_views):
        views.append(f.scalars("f", 2))
        n_lights = f.scalars("I")
        view_lights = f.array(np.float32, 2 * n_lights).reshape(n_lights, 2)
        if lights is None:
            lights = view_lights
        elif len(view_lights) != len(lights):
            raise InputError(
                f"{path}: view {view} has {len(view_lights)} lights, view 0 has {len(lights)}: "
                "views with different light sets are not supported"
            )
    if lights is None:
        raise InputError(f"{path}: n_views: the file has no views")
    if len(lights) == 0:
        raise InputError(f"{path}: n_lights: the views have no lights")
    width, height = f.scalars("I"), f.scalars("I")
    if width < 1 or height < 1:
        raise InputError(f"{path}: width x height is {width}x{height}; both must be >= 1")
    if signature.endswith(b"R"):
        f.array(np.float32, 9 * f.scalars("I"))  # local frame rotations: unused
    components = f.scalars("I")  # btflib: the largest channel's k (checked below)
    code = f.scalars("i")
    color_mean = np.array(f.scalars("f", 3), np.float32)
    color_matrix = f.array(np.float32, 9).reshape(3, 3)
    if code not in COLOR_MODEL_CODES:
        raise InputError(f"{path}: colour model {code} is not supported")
    for label, values in (("colour mean", color_mean), ("colour transformation", color_matrix)):
        if not np.all(np.isfinite(values)):
            raise InputError(f"{path}: {label} has NaN or infinite values")
    n_lights, n_pairs, n_texels = len(lights), n_views * len(lights), width * height

    u_blocks, sigmas, eigentextures = [], [], []
    for channel in channels:
        where = f"{path}: channel {channel!r}"
        scalar = f.scalars("B")
        if scalar not in _SCALAR_TYPES:
            raise InputError(f"{where}: scalar size {scalar} not 2, 4 or 8")
        dtype = _SCALAR_TYPES[scalar]
        k, n_rows, n_cols = f.scalars("I"), f.scalars("I"), f.scalars("I")
        if k < 1:
            raise InputError(f"{where}: k (components) is 0")
        # Sizes first: a corrupt size is named, not read as a huge truncated array.
        if (n_rows, n_cols) == (n_pairs, n_texels):
            transposed = False
        elif (n_rows, n_cols) == (n_texels, n_pairs):
            transposed = True  # images stacked column-wise: the factors' roles swap
        else:
            raise InputError(
                f"{where}: factor sizes {n_rows}x{n_cols} do not match "
                f"{n_views} views x {n_lights} lights and {width}x{height} texels"
            )
        sigma = f.array(dtype, k).astype(np.float32)
        u = f.array(dtype, n_rows * k).reshape(n_rows, k).astype(np.float32)
        sxv = f.array(dtype, n_cols * k).reshape(n_cols, k).astype(np.float32)
        for label, values in (("S", sigma), ("U", u), ("SxV", sxv)):
            if not np.all(np.isfinite(values)):
                bad = int(np.count_nonzero(~np.isfinite(values)))
                raise InputError(f"{where}: {label} has {bad} NaN or infinite values")
        # Equal sizes (texels == pairs) are read in the normal layout, as btflib's
        # get_fmf_eigen_abrdfs does; write_ubo2014 never writes the other one then.
        if transposed:
            u, sxv = (sxv / np.where(sigma > 0, sigma, 1)).astype(np.float32), u * sigma
        u_blocks.append(u)
        sigmas.append(sigma)
        eigentextures.append(sxv.reshape(height, width, k))

    if f.pos != len(f.data):
        raise InputError(
            f"{path}: {len(f.data) - f.pos} bytes after the last channel's factors: a damaged "
            "or concatenated file"
        )
    ks = [len(sigma) for sigma in sigmas]
    if components not in (max(ks), sum(ks)):
        raise InputError(
            f"{path}: the components field says {components}, but the channels hold k = "
            f"{', '.join(map(str, ks))} (the field is the largest, {max(ks)})"
        )

    # Our rows: (light, view, channel) C order; the file's: view-major, light fastest.
    light_idx, view_idx = np.meshgrid(np.arange(n_lights), np.arange(n_views), indexing="ij")
    file_rows = (view_idx * n_lights + light_idx).ravel()  # for our (light, view) order
    n_channels = len(channels)
    total_k = sum(u.shape[1] for u in u_blocks)
    big_u = np.zeros((n_pairs * n_channels, total_k), np.float32)
    offset = 0
    for c, u in enumerate(u_blocks):
        big_u[c::n_channels, offset : offset + u.shape[1]] = u[file_rows]
        offset += u.shape[1]
    try:
        return BTF(
            big_u,
            np.concatenate(sigmas),
            np.concatenate(eigentextures, axis=2),
            np.rad2deg(lights),
            np.rad2deg(np.array(views, np.float32)),
            tuple(channels),
            COLOR_MODEL_CODES[code],
            color_mean,
            color_matrix,
        )
    except InputError as exc:  # directions, colour model against channels
        raise InputError(f"{path}: {exc}") from None


def write_ubo2014(
    path: str | os.PathLike,
    *,
    eigen_abrdfs: Sequence[np.ndarray],
    singular_values: Sequence[np.ndarray],
    eigentextures: Sequence[np.ndarray],
    light_dirs: np.ndarray,
    view_dirs: np.ndarray,
    color_model: str = "RGB",
    color_mean: Sequence[float] = (0.0, 0.0, 0.0),
    color_matrix: np.ndarray | None = None,
    channels: Sequence[str] = ("R", "G", "B"),
    scalar_size: int = 4,
    layout: str = "abrdfs",
) -> Path:
    """Write per-channel factors in the DFMF layout (version-4 meta block), atomically.

    Every shape is checked before anything is written.

    Parameters
    ----------
    eigen_abrdfs : per channel (n_views * n_lights, k_c), rows view-major (light fastest)
    singular_values : per channel (k_c,)
    eigentextures : per channel (height, width, k_c), the SxV factor
    light_dirs, view_dirs : (n, 2) (theta, phi) degrees
    color_model : str
        A value of :data:`COLOR_MODEL_CODES`.
    scalar_size : {2, 4, 8}
        float16, float32 or float64.
    layout : {"abrdfs", "images"}
        "abrdfs" (btflib's files): U holds the ABRDFs' factor, SxV the texels'.
        "images": the transposed matrix (U rows are texels, SxV rows direction
        pairs), which some Bonn files use; the reader accepts both. Refused when
        width * height == n_views * n_lights: the file could not say which it is.

    Raises
    ------
    InputError
        Inconsistent shapes or options, values the scalar type cannot hold, channel
        names that are not printable ASCII, a colour model other than RGB on other
        than three channels (nothing is written).

    Example
    -------
    >>> import tempfile
    >>> u = np.linalg.qr(np.random.default_rng(0).normal(size=(2, 2)))[0]
    >>> path = Path(tempfile.mkdtemp()) / "t.btf"
    >>> _ = write_ubo2014(path, eigen_abrdfs=[u], singular_values=[np.ones(2)],
    ...                   eigentextures=[np.ones((3, 4, 2))], channels=("L",),
    ...                   light_dirs=[[0, 0], [45, 90]], view_dirs=[[0, 0]])
    >>> read_ubo2014(path).shape
    (3, 4)
    """
    check_writable(path, "write_ubo2014 path")  # a folder, or one that cannot be written
    codes = {name: code for code, name in COLOR_MODEL_CODES.items()}
    if color_model not in codes:
        raise InputError(f"color_model: {color_model!r} not one of {sorted(codes)}")
    if scalar_size not in _SCALAR_TYPES:
        raise InputError(f"scalar_size: {scalar_size!r} not one of {sorted(_SCALAR_TYPES)}")
    if layout not in ("abrdfs", "images"):
        raise InputError(f"layout: {layout!r} not 'abrdfs' or 'images'")
    light_dirs = check_directions(light_dirs, "light_dirs")
    view_dirs = check_directions(view_dirs, "view_dirs")
    channels = _check_channel_names(channels)
    if color_model != "RGB" and len(channels) != 3:
        raise InputError(
            f"color_model: {color_model!r} is a 3-channel transform; got {len(channels)} "
            f"channels {channels} (use 'RGB' for another count)"
        )
    n_pairs = len(light_dirs) * len(view_dirs)
    us, sigmas, sxvs = _check_factors(
        eigen_abrdfs, singular_values, eigentextures, channels, n_pairs
    )
    height, width = sxvs[0].shape[:2]
    if layout == "images" and height * width == n_pairs:
        raise InputError(
            f"layout: 'images' with {height}x{width} = {height * width} texels and "
            f"{len(view_dirs)} views x {len(light_dirs)} lights = {n_pairs} direction pairs "
            "is ambiguous (every reader takes such a file as 'abrdfs'); write layout='abrdfs'"
        )
    sxvs_flat = [w.reshape(height * width, -1) for w in sxvs]
    if layout == "images":  # the transposed factorization: texels' factor first
        us, sxvs_flat = (
            [w / np.where(s > 0, s, 1) for w, s in zip(sxvs_flat, sigmas, strict=True)],
            [u * s for u, s in zip(us, sigmas, strict=True)],
        )
    _check_range(us, sigmas, sxvs_flat, channels, scalar_size)
    mean = np.asarray(color_mean, dtype=np.float64)
    matrix = np.eye(3) if color_matrix is None else np.asarray(color_matrix, dtype=np.float64)
    if mean.shape != (3,) or matrix.shape != (3, 3):
        raise InputError(
            f"color_mean, color_matrix: expected (3,) and (3, 3), got {mean.shape}, {matrix.shape}"
        )
    if not (np.all(np.isfinite(mean)) and np.all(np.isfinite(matrix))):
        raise InputError("color_mean, color_matrix: have NaN or infinite values")

    dtype = np.dtype(_SCALAR_TYPES[scalar_size]).newbyteorder("<")
    lights = np.deg2rad(light_dirs).astype("<f4")
    views = np.deg2rad(view_dirs).astype("<f4")
    meta = struct.pack("<I", 4) + b"\0" * 240 + struct.pack("<4f", 1.0, 1.0, 1.0, 1.0)
    meta += struct.pack("<II", 0, 0)  # cosine flag, XML length
    meta += struct.pack("<I", len(channels))
    for name in channels:
        meta += struct.pack("<I", len(name)) + name.encode("latin-1")
    parts = [SIGNATURE, struct.pack("<I", len(meta) + 4), meta, struct.pack("<I", len(views))]
    for view in views:
        parts += [view.tobytes(), struct.pack("<I", len(lights)), lights.tobytes()]
    parts += [struct.pack("<II", width, height), struct.pack("<I", 0)]  # no rotations
    # The total-components field holds the largest channel's k, as btflib writes it.
    parts += [
        struct.pack("<Ii", max(s.size for s in sigmas), codes[color_model]),
        mean.astype("<f4").tobytes(),
        matrix.astype("<f4").tobytes(),
    ]
    for u, s, w in zip(us, sigmas, sxvs_flat, strict=True):
        parts += [struct.pack("<BIII", scalar_size, s.size, u.shape[0], w.shape[0])]
        parts += [s.astype(dtype).tobytes(), u.astype(dtype).tobytes(), w.astype(dtype).tobytes()]
    path = Path(path)
    with atomic_path(path) as tmp:
        tmp.write_bytes(b"".join(parts))
    return path


def _check_channel_names(channels) -> tuple[str, ...]:
    """Channel names as a tuple, or InputError: each non-empty printable ASCII (the file
    stores bytes that btflib and pysmtb read as ASCII)."""
    if isinstance(channels, str):
        channels = (channels,)
    names = tuple(channels)
    for index, name in enumerate(names):
        if not isinstance(name, str) or not name or not (name.isascii() and name.isprintable()):
            raise InputError(f"channels[{index}]: {name!r} is not a non-empty printable ASCII name")
    return names


def _check_range(us, sigmas, sxvs, channels, scalar_size: int) -> None:
    """InputError naming the factor and channel whose values the scalar type cannot hold
    (float16 overflows to inf above 65504)."""
    limit = float(_SCALAR_LIMITS[scalar_size])
    dtype = _SCALAR_TYPES[scalar_size]
    for c, name in enumerate(channels):
        for label, values in (
            ("eigen_abrdfs", us[c]),
            ("singular_values", sigmas[c]),
            ("eigentextures", sxvs[c]),
        ):
            largest = float(np.abs(values).max())
            if largest > limit:
                raise InputError(
                    f"{label}[{c}] (channel {name!r}): largest |value| {largest:.6g} exceeds "
                    f"{limit:g}, the largest scalar_size={scalar_size} float; use a larger "
                    "scalar_size or rescale"
                )
            # Underflow: a singular value, or a whole component, flushed to zero is lost.
            values = np.asarray(values).reshape(len(values), -1)
            if label == "singular_values":
                values = values.T  # one component per column
            zero = values.astype(dtype) == 0
            kept = (values != 0).any(axis=0)
            lost = np.flatnonzero(zero.all(axis=0) & kept)
            if not lost.size:
                continue
            largest = float(np.abs(values[:, lost]).max())
            shown = (
                f"{label}[{c}] (channel {name!r}): {lost.size} of {int(kept.sum())} "
                f"component(s) (|value| up to {largest:.3g}) are below the smallest "
                f"scalar_size={scalar_size} float and would be written as 0"
            )
            if lost.size == kept.sum():  # the channel would read back as nothing
                raise InputError(f"{shown}: the channel would be lost; use a larger "
                                 "scalar_size or rescale")  # fmt: skip
            log.warning("%s (the others are kept)", shown)


def _check_factors(eigen_abrdfs, singular_values, eigentextures, channels, n_pairs: int):
    """The per-channel factors as float64 arrays, or InputError naming what disagrees."""
    counts = {
        "channels": len(channels),
        "eigen_abrdfs": len(eigen_abrdfs),
        "singular_values": len(singular_values),
        "eigentextures": len(eigentextures),
    }
    if len(set(counts.values())) != 1 or counts["channels"] < 1:
        raise InputError(f"one factor per channel needed; got {counts}")
    us: list[np.ndarray] = []
    sigmas: list[np.ndarray] = []
    sxvs: list[np.ndarray] = []
    for c, name in enumerate(channels):
        u = np.asarray(eigen_abrdfs[c], dtype=np.float64)
        s = np.asarray(singular_values[c], dtype=np.float64)
        w = np.asarray(eigentextures[c], dtype=np.float64)
        where = f"channel {name!r}"
        if s.ndim != 1 or s.size < 1:
            raise InputError(f"singular_values[{c}] ({where}): expected (k,), got {s.shape}")
        k = s.size
        if u.shape != (n_pairs, k):
            raise InputError(
                f"eigen_abrdfs[{c}] ({where}): expected ({n_pairs}, {k}) for the direction "
                f"pairs (views x lights) and k = {k} singular values, got {u.shape}"
            )
        if w.ndim != 3 or w.shape[2] != k or w.shape[0] < 1 or w.shape[1] < 1:
            raise InputError(
                f"eigentextures[{c}] ({where}): expected (height, width, {k}) with height "
                f"and width >= 1, got {w.shape}"
            )
        if sxvs and w.shape[:2] != sxvs[0].shape[:2]:
            raise InputError(
                f"eigentextures[{c}] ({where}): {w.shape[0]}x{w.shape[1]} texels, channel "
                f"{channels[0]!r} has {sxvs[0].shape[0]}x{sxvs[0].shape[1]}"
            )
        for array, label in ((u, "eigen_abrdfs"), (s, "singular_values"), (w, "eigentextures")):
            if not np.all(np.isfinite(array)):
                raise InputError(f"{label}[{c}] ({where}): has NaN or infinite values")
        us.append(u)
        sigmas.append(s)
        sxvs.append(w)
    return us, sigmas, sxvs
