"""Extrapolate a BTF sample to a large sample: pixel-wise (Eq. 6) and texture optimization.

Both methods synthesize only new eigentextures V~Sigma for the large sample; the
eigen-ABRDFs U of the measured sample are reused (Sec. 3.3 of the cross-device
paper). The inputs are the sample BTF and four images of the large sample lit from
theta 22 deg at azimuths 0, 90, 180, 270 (scans, or rows of a reference BTF).

Example
-------
>>> from imagemap.btf.extrapolate import extrapolate, PixelwiseParams
>>> params = PixelwiseParams(radius=0, ws=0.0, wc=1.0)
>>> big = extrapolate(sample, scans, params)  # doctest: +SKIP
"""

from __future__ import annotations

import logging
import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from imagemap.btf.constraints import (
    TABLE1_RESPONSE,
    ScannerResponse,
    align_histograms,
    color_correct,
    constraint_bands,
    histogram_alignment_factors,
    stack_neighbourhood,
)
from imagemap.btf.core import BTF
from imagemap.io import InputError

__all__ = [
    "BLACK_SCAN_LEVEL",
    "CONSTRAINT_AZIMUTHS",
    "FLAT_SCAN_STD",
    "check_scans",
    "CONSTRAINT_THETA",
    "PixelwiseParams",
    "ExtrapolationParams",
    "TextureOptimizationParams",
    "constraint_images",
    "prepare_scans",
    "pixelwise",
    "texture_optimization",
    "tile",
    "extrapolate",
]

log = logging.getLogger("imagemap")

#: The paper's constraint images: topmost view, light theta 22 deg, these azimuths.
CONSTRAINT_THETA = 22.0
CONSTRAINT_AZIMUTHS = (0.0, 90.0, 180.0, 270.0)

#: The pixel-wise method's searches (:data:`imagemap.core.search.INDEX_BACKENDS`).
PIXELWISE_BACKENDS = ("pca_kdtree", "kdtree", "exact", "pynndescent")

#: Former names of the pixel-wise search (``search=``) -> the index that ran them.
_OLD_SEARCH_NAMES = {"approximate": "pca_kdtree", "exact": "kdtree", "pynndescent": "pynndescent"}

#: A scan whose brightest channel value is at or below this (fraction of full scale) saw
#: no light: 2/255 is an 8-bit scanner's black (noise and offset; Table 1's offsets are
#: 0.00-0.01, so a lit scan of any real material reaches far above).
BLACK_SCAN_LEVEL = 2.0 / 255.0

#: A scan whose standard deviation is below this shows no pattern to match (an 8-bit
#: quantization step is 1/255; a scan of any textured sample varies by many steps).
FLAT_SCAN_STD = 0.5 / 255.0


def _weights(ws: float, wc: float) -> None:
    for name, value in (("ws", ws), ("wc", wc)):
        if not np.isfinite(value) or value < 0:
            raise InputError(f"{name}: a finite weight >= 0, got {value}")
    if ws == 0 and wc == 0:
        raise InputError("ws, wc: both 0 leave no constraint to match (give one > 0)")


def check_scans(scans: Sequence[np.ndarray], names: Sequence[str] | None = None) -> list:
    """Four usable scans, or InputError naming the one at fault.

    Refused: not four, not (H, W, 3), NaN, black (no value above
    :data:`BLACK_SCAN_LEVEL`), a black channel, flat (std below :data:`FLAT_SCAN_STD`),
    and two identical scans (one scan given twice: the lamp sides would agree by
    construction and the surface descriptors vanish).

    Example
    -------
    >>> scan = np.random.default_rng(0).random((8, 8, 3))
    >>> check_scans([scan, scan + 0.01, scan + 0.02, scan + 0.03], ["a", "b", "c", "d"])[0].shape
    (8, 8, 3)
    >>> check_scans([scan, scan, scan, scan])  # doctest: +IGNORE_EXCEPTION_DETAIL
    Traceback (most recent call last):
    imagemap.errors.InputError: scans[1] is the same image as scans[0] ...
    """
    if len(scans) != 4:
        raise InputError(
            f"scans: expected four images (azimuths 0, 90, 180, 270), got {len(scans)}"
        )
    names = list(names) if names is not None else [f"scans[{i}]" for i in range(4)]
    out: list[np.ndarray] = []
    for name, scan in zip(names, scans, strict=True):
        array = np.asarray(scan, dtype=np.float32)
        if array.ndim != 3 or array.shape[2] != 3:
            raise InputError(f"{name}: expected an (H, W, 3) image, got shape {array.shape}")
        if not np.all(np.isfinite(array)):
            raise InputError(f"{name}: has NaN or infinite values")
        brightest = array.reshape(-1, 3).max(axis=0)
        if brightest.max() <= BLACK_SCAN_LEVEL:
            raise InputError(f"{name}: the scan is black (no value above {BLACK_SCAN_LEVEL:.4f})")
        if brightest.min() <= BLACK_SCAN_LEVEL:
            channel = "RGB"[int(np.argmin(brightest))]
            raise InputError(f"{name}: channel {channel} is black everywhere")
        if float(array.std()) < FLAT_SCAN_STD:
            raise InputError(f"{name}: the scan is flat (one value everywhere): no pattern")
        for other_name, other in zip(names, out, strict=False):
            if other.shape == array.shape and np.array_equal(other, array):
                raise InputError(
                    f"{name} is the same image as {other_name}: four scans under four lamp "
                    "directions are needed"
                )
        out.append(array)
    return out


@dataclass(frozen=True)
class PixelwiseParams:
    """Parameters of the pixel-wise method (Eqs. 5-6).

    Parameters
    ----------
    radius : int
        Neighbourhood radius R of the extended constraint vectors.
    ws, wc : float
        Weights of the surface descriptors and the colours.
    backend : {"pca_kdtree", "kdtree", "exact", "pynndescent"}
        The nearest-neighbour index (:func:`imagemap.core.search.make_index`).
        "pca_kdtree": vectors of more than 16 dimensions are reduced by PCA (fit on
        the sample) to 16, then searched exactly with a k-d tree. "kdtree": exact, a
        k-d tree up to 16 dimensions, chunked brute force (BLAS) beyond. "exact":
        brute force always. "pynndescent": pynndescent's graph (seeded; compiles on
        first use).
    seed : int
        Seed of the approximate search.
    neighbours : int
        1: copy the nearest texel's row (Eq. 6). K > 1: the mean of the K nearest
        texels' rows (not in the paper): where the scans leave a texel's BTF open,
        the mean of the candidates estimates it with less squared error than any one
        of them; where they determine it, it blurs. "approximate" or "exact" search.
    """

    radius: int = 0
    ws: float = 0.0
    wc: float = 1.0
    backend: str = "pca_kdtree"
    seed: int = 0
    neighbours: int = 1

    def __post_init__(self) -> None:
        if self.backend not in PIXELWISE_BACKENDS:
            raise InputError(f"backend: {self.backend!r} is not one of {PIXELWISE_BACKENDS}")
        if isinstance(self.radius, bool) or not isinstance(self.radius, int | np.integer):
            raise InputError(f"radius: an integer >= 0, got {self.radius!r}")
        if self.radius < 0:
            raise InputError(f"radius: an integer >= 0, got {self.radius}")
        _weights(self.ws, self.wc)


def ExtrapolationParams(  # noqa: N802 - the deprecated class name
    radius: int = 0,
    ws: float = 0.0,
    wc: float = 1.0,
    search: str = "approximate",
    seed: int = 0,
    neighbours: int = 1,
) -> PixelwiseParams:
    """Deprecated: :class:`PixelwiseParams` under its former name and vocabulary.

    ``search`` "approximate" is now ``backend="pca_kdtree"`` and "exact"
    ``backend="kdtree"`` (the same searches as before).
    """
    warnings.warn(
        "ExtrapolationParams is deprecated; use PixelwiseParams (search= is now backend=: "
        "'approximate' -> 'pca_kdtree', 'exact' -> 'kdtree')",
        DeprecationWarning,
        stacklevel=2,
    )
    if search not in _OLD_SEARCH_NAMES:
        raise InputError(f"search: {search!r} is not 'approximate', 'exact' or 'pynndescent'")
    return PixelwiseParams(
        radius, ws, wc, backend=_OLD_SEARCH_NAMES[search], seed=seed, neighbours=neighbours
    )


@dataclass(frozen=True)
class TextureOptimizationParams:
    """Texture optimization (Kwatra et al. 2005) through :mod:`imagemap.core.engine`.

    Parameters
    ----------
    radius : int
        Window radius R at every scale (window 2R+1; the paper: R = 8).
    levels : int
        Scales 1, 2, 4, ... (the paper: 3 levels, scales 4, 2, 1).
    ws, wc : float
        Weights baked into the guide bands [ws n1, ws n2, wc I0 .. wc I270].
    matched_components : int
        Leading eigentextures matched (weight > 0); the rest are carried.
    appearance_weight : float
        Weight of the matched eigentextures, relative to the leading one's
        standard deviation (bands are not normalized; guide bands are in the
        constraint units).
    stride : int
        Spacing of query windows (Kwatra: a sparse grid).
    max_iterations : int
        EM iterations per level at most.
    pca_max_components : int
        Window features kept after PCA.
    backend : str
        The engine's nearest-neighbour backend.
    final_copy : bool
        After the engine, give each texel the V Sigma row of its own match in the
        final source map (no averaging in eigen-space) instead of the vote's mean.
    seed : int
    """

    radius: int = 8
    levels: int = 3
    ws: float = 1.0
    wc: float = 10.0
    matched_components: int = 8
    appearance_weight: float = 1.0
    stride: int = 4
    max_iterations: int = 4
    pca_max_components: int = 24
    backend: str = "patchmatch"
    final_copy: bool = False
    seed: int = 0

    def __post_init__(self) -> None:
        for name in ("radius", "levels", "matched_components", "stride", "max_iterations"):
            value = getattr(self, name)
            low = 0 if name == "radius" else 1
            if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < low:
                raise InputError(f"{name}: an integer >= {low}, got {value!r}")
        _weights(self.ws, self.wc)
        if not (np.isfinite(self.appearance_weight) and self.appearance_weight >= 0):
            raise InputError(
                f"appearance_weight: a finite weight >= 0, got {self.appearance_weight}"
            )


def constraint_images(
    btf: BTF, *, theta: float = CONSTRAINT_THETA, azimuths: Sequence[float] = CONSTRAINT_AZIMUTHS
) -> list[np.ndarray]:
    """The BTF's own four constraint images: topmost view, light at (theta, azimuth).

    Returns linear RGB (H, W, 3) float32 images, decompressed one at a time.
    """
    view = btf.nearest_view(0.0, 0.0)
    images = []
    for phi in azimuths:
        light = btf.nearest_light(theta, phi)
        found = btf.light_dirs[light]
        if abs(found[0] - theta) > 3 or (theta > 0 and _angle_gap(found[1], phi) > 3):
            log.warning("constraint light (%g, %g) not sampled; using (%g, %g)", theta, phi, *found)
        images.append(btf.image(light, view))
    return images


def _angle_gap(a: float, b: float) -> float:
    return abs((float(a) - float(b) + 180.0) % 360.0 - 180.0)


def prepare_scans(
    scans: Sequence[np.ndarray],
    reference_images: Sequence[np.ndarray],
    *,
    response: ScannerResponse | None = TABLE1_RESPONSE,
) -> list[np.ndarray]:
    """Colour-correct four scans (Table 1) and align their histograms to the BTF's (Eqs. 1-2).

    Parameters
    ----------
    scans : four (H, W, 3) images in [0, 1] as the scanner wrote them.
    reference_images : the sample BTF's four constraint images.
    response : ScannerResponse or None
        None when the scans are already linear.
    """
    scans = check_scans(scans)
    corrected = [color_correct(s, response=response) if response else s for s in scans]
    factors = histogram_alignment_factors(reference_images, corrected)
    return align_histograms(corrected, factors)


def _search(sample: np.ndarray, target: np.ndarray, params: PixelwiseParams) -> np.ndarray:
    """Index of the nearest sample row for every target row (Eq. 6): (n,), or (n, K)
    for ``params.neighbours`` = K > 1."""
    from imagemap.core.search import make_index  # deferred: search backends

    # Bands with weight 0 are 0 everywhere: they cost time and change nothing.
    used = np.any(sample != 0, axis=0) | np.any(target != 0, axis=0)
    sample, target = sample[:, used], target[:, used]
    k = int(params.neighbours)
    if k < 1:
        raise InputError(f"neighbours: at least 1, got {k}")
    index = make_index(params.backend, sample, seed=params.seed)
    if k == 1:
        return index.query(target)[0]
    if not hasattr(index, "query_k"):
        raise InputError(
            f"neighbours > 1 needs backend 'pca_kdtree' or 'kdtree', not {params.backend!r}"
        )
    return index.query_k(target, k)


def pixelwise(
    sample: BTF,
    sample_images: Sequence[np.ndarray],
    target_images: Sequence[np.ndarray],
    params: PixelwiseParams = PixelwiseParams(),
) -> tuple[BTF, np.ndarray]:
    """Pixel-wise extrapolation (Eq. 6): copy the V Sigma row of the nearest constraint vector.

    Parameters
    ----------
    sample : BTF
        The measured sample.
    sample_images : four (h, w, 3) constraint images of the sample.
    target_images : four (H, W, 3) constraint images of the large sample (prepared
        scans: colour-corrected and histogram-aligned).
    params : PixelwiseParams

    Returns
    -------
    btf : BTF
        Shares the sample's U; eigentextures (H, W, k).
    source : ndarray (H, W, 2) int32
        Sample texel (y, x) copied to each output texel.

    Example
    -------
    >>> big, source = pixelwise(sample, constraint_images(sample), scans)  # doctest: +SKIP
    """
    if sample_images[0].shape[:2] != sample.shape:
        raise InputError(
            f"sample_images: shape {sample_images[0].shape[:2]} differs from the sample's "
            f"{sample.shape}"
        )
    kwargs = {"ws": params.ws, "wc": params.wc}
    sample_c = stack_neighbourhood(constraint_bands(sample_images, **kwargs), radius=params.radius)
    target_c = stack_neighbourhood(constraint_bands(target_images, **kwargs), radius=params.radius)
    height, width = target_c.shape[:2]
    index = _search(
        sample_c.reshape(-1, sample_c.shape[2]), target_c.reshape(-1, target_c.shape[2]), params
    )
    flat = sample.eigentextures.reshape(-1, sample.n_components)
    if index.ndim == 2:  # the mean of the K nearest; the source map shows the nearest
        eigentextures = np.zeros((len(index), flat.shape[1]), np.float32)
        for column in index.T:
            eigentextures += flat[column]
        eigentextures = (eigentextures / index.shape[1]).reshape(height, width, -1)
        index = index[:, 0]
    else:
        eigentextures = flat[index].reshape(height, width, -1)
    source = np.stack(np.unravel_index(index, sample.shape), axis=-1).reshape(height, width, 2)
    return sample.with_eigentextures(eigentextures), source.astype(np.int32)


def tile(sample: BTF, shape: tuple[int, int]) -> BTF:
    """The naive baseline: the sample's eigentextures repeated to ``shape``."""
    reps = (-(-shape[0] // sample.shape[0]), -(-shape[1] // sample.shape[1]), 1)
    tiled = np.tile(sample.eigentextures, reps)[: shape[0], : shape[1]]
    return sample.with_eigentextures(np.ascontiguousarray(tiled))


def texture_optimization(
    sample: BTF,
    sample_images: Sequence[np.ndarray],
    target_images: Sequence[np.ndarray],
    params: TextureOptimizationParams = TextureOptimizationParams(),
    *,
    quiet: bool = True,
) -> tuple[BTF, object]:
    """Texture optimization through the shared engine, coarse to fine.

    Guide bands are the per-texel constraint bands [ws n1, ws n2, wc I0..I270]
    (the engine's windows give the neighbourhood), appearance bands are the
    eigentextures V Sigma; only the leading ``matched_components`` are matched,
    all are voted.

    Returns
    -------
    btf : BTF
        Shares the sample's U.
    result : imagemap.core.engine.EngineResult
        Source map, costs and timings of the engine.
    """
    from imagemap.core.engine import (
        EngineParams,
        Mapping,
        synthesize,
        uniform_levels,
    )  # deferred: engine
    from imagemap.core.pyramid import gaussian_pyramid  # deferred: engine

    kwargs = {"ws": params.ws, "wc": params.wc}
    sample_guide = constraint_bands(sample_images, **kwargs)
    target_guide = constraint_bands(target_images, **kwargs)
    k = sample.n_components
    matched = min(params.matched_components, k)
    spread = sample.eigentextures.reshape(-1, k).std(axis=0)
    # One weight for all matched bands, per std of the leading one: later bands then
    # count in proportion to their own spread (their energy), not equally.
    weights = np.zeros(k)
    weights[:matched] = params.appearance_weight / max(float(spread[0]), 1e-12)
    window = 2 * params.radius + 1
    engine_params = EngineParams(
        levels=uniform_levels((window,) * params.levels, max_iterations=params.max_iterations),
        guide_weights=(1.0,) * sample_guide.shape[2],
        appearance_weights=tuple(float(w) for w in weights),
        position_weight=0.0,
        pca_max_components=params.pca_max_components,
        backend=params.backend,
        normalize_bands=False,
        guide_padding="reflect",
        stride=params.stride,
    )
    query = [Mapping(guide=g) for g in gaussian_pyramid(target_guide, levels=params.levels)]
    exemplar = [
        Mapping(guide=g, appearance=a)
        for g, a in zip(
            gaussian_pyramid(sample_guide, levels=params.levels),
            gaussian_pyramid(sample.eigentextures, levels=params.levels),
            strict=True,
        )
    ]
    result = synthesize(query, [exemplar], engine_params, seed=params.seed, quiet=quiet)
    if params.final_copy:
        # One exemplar: source (H, W, 3) is (0, y, x) of each texel's match.
        copied = sample.eigentextures[result.source[..., 1], result.source[..., 2]]
        return sample.with_eigentextures(np.ascontiguousarray(copied)), result
    return sample.with_eigentextures(result.appearance[0]), result


def extrapolate(
    sample: BTF,
    scans: Sequence[np.ndarray],
    params: PixelwiseParams | TextureOptimizationParams = PixelwiseParams(),
    *,
    response: ScannerResponse | None = TABLE1_RESPONSE,
    quiet: bool = True,
) -> BTF:
    """The whole pipeline: sample BTF + four scans -> BTF of the large sample.

    The scans are colour-corrected (``response``; None if already linear) and
    histogram-aligned to the sample's own constraint images, then the method of
    ``params`` (pixel-wise or texture optimization) synthesizes V~Sigma.

    Example
    -------
    >>> big = extrapolate(sample, [scan0, scan90, scan180, scan270])  # doctest: +SKIP
    """
    started = time.perf_counter()
    sample_images = constraint_images(sample)
    target_images = prepare_scans(scans, sample_images, response=response)
    if isinstance(params, TextureOptimizationParams):
        result, _ = texture_optimization(sample, sample_images, target_images, params, quiet=quiet)
    else:
        result, _ = pixelwise(sample, sample_images, target_images, params)
    log.info(
        "extrapolated %s -> %s in %.1f s", sample.shape, result.shape, time.perf_counter() - started
    )
    return result
