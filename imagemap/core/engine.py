"""The guided hard-EM synthesis engine, shared by every front end.

A :class:`Mapping` is a stack of *guide* bands (known for query and exemplars)
beside *appearance* bands (known for exemplars, to be made for the query) and a
mask. For every k x k query window the engine finds the most similar exemplar
window (guide + current appearance + relative position to the mask centroid,
weighted, PCA-reduced, nearest-neighbour search: the hard E-step) and sets every
pixel to the Gaussian-weighted mean of the k^2 estimates that the overlapping
matches give it (the M-step), coarse to fine. Between levels the selected source
coordinates are propagated (x2) and the finer exemplar level is sampled, never
interpolated intensities (Hassner & Basri 2006, Sec. 2).

The target the iterations minimise is the sum over query windows of the exact
weighted window distance to their match (the negative log of the paper's
similarity). With the window weighting equal to the voting weights, the vote is
the exact minimiser for fixed matches, and a new match replaces the previous one
only where the exact distance improves, so the recorded target never increases
at a level whatever the search backend (generalised EM).

Examples
--------
A single-level guided synthesis: the query guide is a shifted exemplar guide.

>>> rng = np.random.default_rng(0)
>>> guide = rng.random((32, 32, 1)).astype(np.float32)
>>> exemplar = Mapping(guide=guide, appearance=guide * 2)
>>> query = Mapping(guide=np.roll(guide, 3, axis=1))
>>> params = EngineParams(patch_sizes=(5,), backend="exact", guide_weights=(1.0,),
...                       appearance_weights=(1.0,))
>>> result = synthesize([query], [[exemplar]], params)
>>> result.appearance[0].shape
(32, 32, 1)
"""

from __future__ import annotations

import contextlib
import ctypes
import logging
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from scipy import ndimage
from threadpoolctl import threadpool_limits

from imagemap.core import kernels as _kernels
from imagemap.core.pyramid import collapse_laplacian, expand
from imagemap.core.search import make_index
from imagemap.progress import progress

__all__ = [
    "BACKENDS",
    "VOTES",
    "EngineParams",
    "EngineResult",
    "Mapping",
    "ReleasableLevels",
    "synthesize",
]

log = logging.getLogger("imagemap")

BACKENDS = ("patchmatch", "exact", "pynndescent")
VOTES = ("mean", "mode")
_CHUNK = 16384  # windows per block when extracting features: bounds memory
_GATHER_ROWS = 2048  # windows per gather of one channel into such a block (see _Windows)
# Fixed PatchMatch work split (results do not depend on the thread count): bands of
# at least _BAND_ROWS rows, since propagation does not cross band borders.
_MAX_BANDS = 8
# Below this many multiply-adds, PatchMatch starts from an exact search, not at random.
_EXACT_START_FLOPS = 2e9
_BAND_ROWS = 64
_SOURCE_ROWS = 256  # rows per block when the dense source map is made
#: Quantized features: integer steps from 0 to the largest magnitude (int16), and the
#: margin of that largest magnitude over the largest value in the PCA samples.
_FEATURE_RANGE = 32767
_FEATURE_MARGIN = 2.0
#: Share of a level's windows, the worst fits of the guide after propagation, that
#: ``EngineParams.guide_reseed`` may give a match on guide and position only.
RESEED_WORST = 0.1
#: Share of the finest level's windows, the worst fits of the guide after the EM, that
#: ``EngineParams.final_reseed`` may give a match on guide and position only. Larger
#: than ``RESEED_WORST``: no EM iteration follows that could vote a good guide fit away.
FINAL_RESEED_WORST = 0.25

#: What the appearance bands of a level are: its Gaussian level or its Laplacian band.
APPEARANCE_PYRAMIDS = ("gaussian", "laplacian")


@dataclass(frozen=True)
class Mapping:
    """One pyramid level of a query or exemplar: guide, appearance and mask.

    Parameters
    ----------
    guide : ndarray, shape (H, W, Cg) or (H, W)
        Bands known for query and exemplars (depth bands, constraint images...).
    appearance : ndarray, shape (H, W, Ca) or (H, W), optional
        Bands to synthesise: given for exemplars, None for the query.
    mask : ndarray of bool, shape (H, W), optional
        Where the mapping matters (the object); None means everywhere.
    """

    guide: np.ndarray
    appearance: np.ndarray | None = None
    mask: np.ndarray | None = None

    def __post_init__(self) -> None:
        guide = np.asarray(self.guide, dtype=np.float32)
        if guide.ndim == 2:
            guide = guide[..., None]
        if guide.ndim != 3:
            raise ValueError(f"guide must be (H, W) or (H, W, C), got shape {guide.shape}")
        object.__setattr__(self, "guide", guide)
        if self.appearance is not None:
            appearance = np.asarray(self.appearance, dtype=np.float32)
            if appearance.ndim == 2:
                appearance = appearance[..., None]
            if appearance.shape[:2] != guide.shape[:2]:
                raise ValueError(
                    f"appearance {appearance.shape[:2]} and guide {guide.shape[:2]} differ in size"
                )
            object.__setattr__(self, "appearance", appearance)
        if self.mask is not None:
            mask = np.asarray(self.mask, dtype=bool)
            if mask.shape != guide.shape[:2]:
                raise ValueError(f"mask {mask.shape} and guide {guide.shape[:2]} differ in size")
            if not mask.any():
                raise ValueError("mask is empty")
            object.__setattr__(self, "mask", mask)

    @property
    def shape(self) -> tuple[int, int]:
        return self.guide.shape[:2]


class ReleasableLevels(list):
    """A pyramid (list of :class:`Mapping`, finest first) handed over to :func:`synthesize`:
    once the engine has packed a level's bands it calls :meth:`release`, which drops the
    level from the list, so that its arrays are freed during the synthesis if nothing
    else holds them. A plain list is left as it is."""

    def release(self, level: int) -> None:
        self[level] = None


@dataclass(frozen=True)
class EngineParams:
    """Parameters of the engine (front ends wrap them in their own presets).

    Parameters
    ----------
    patch_sizes : tuple of int
        Odd window width per pyramid level, finest first.
    guide_weights, appearance_weights : tuple of float
        One weight per band. With ``normalize_bands`` a weight is per standard
        deviation of its band over the exemplars, so weights are unit-free.
        An appearance weight of 0 carries the band (voted into the output) without
        matching on it.
    position_weight : float
        Weight of the position relative to the mask centroid, in units of the
        mask's RMS radius (0 switches the term off).
    pca_fraction : float
        Fraction of the PCA basis kept, separately for guide and appearance windows.
    pca_max_components : int, optional
        Upper bound on kept components per part.
    pca_samples : int
        Exemplar windows sampled to learn the PCA basis.
    backend : {"patchmatch", "exact", "pynndescent"}
        Nearest-neighbour search of the E-step.
    max_iterations : int
        EM iterations per level at most; 0 gives one pass of matching on guide
        and position and one vote per level (no EM).
    tolerance : float
        Stop a level when the target decreases by less than this fraction.
    patchmatch_passes : int
        PatchMatch passes per E-step (twice as many from a random start).
    normalize_bands : bool
        Divide each band by its standard deviation over the exemplars.
    guide_padding : {"constant", "reflect", "edge"}
        How guide bands are extended beyond the image (constant = 0, for depth).
    stride : int
        Spacing of query windows; 1 matches every pixel.
    init_from_guide : bool
        At the coarsest level, start from matches on guide and position only.
    window_sigma : float
        Standard deviation of the Gaussian window, as a fraction of its width.
    exemplar_costs : tuple of float
        Additive cost of matching into each exemplar (empty: none), in the units of
        the window distance: a preference for some exemplars over others.
    exemplar_costs_at_finest : bool
        Apply ``exemplar_costs`` at the finest level too (at ``feature_level`` and
        every finer level, where that is not the finest). False: the coarser levels
        settle which exemplar each region comes from, and the finest level may take
        a small feature from any exemplar.
    guide_reseed : float
        At every level but the coarsest, after the coarser level's matches are
        propagated, also match on guide and position only, and take that match
        where the propagated one is among the worst-fitting tenth of the guide
        (``RESEED_WORST``) and the new one fits in less than this fraction of its
        distance (0: off). Without it a feature that only the finer level's guide
        resolves is voted away by the coarser level's appearance.
    final_reseed : float
        After the finest level's EM, match once more on guide and position only,
        and take that match where the EM's match is among the worst-fitting
        quarter of the guide (``FINAL_RESEED_WORST``), the new one fits in less
        than this fraction of its distance (0: off) and carries at least as much
        appearance detail (a reseed may draw a feature, never erase one). The EM's
        appearance term keeps what the coarser levels drew: where they lost a small
        feature (an eye blurred away at a coarse level), no window that draws it
        fits the blurred estimate, and the finest level cannot bring it back. The matches
        that make the copy (``copy_source``) then follow the relief there; the
        voted appearance does not change.
    feature_level : int
        The level whose windows draw the small features: ``final_reseed`` runs after
        its EM, and ``exemplar_costs_at_finest`` refers to it and the levels finer
        (0: the finest). Where it is a coarser level (a large map, whose finest
        windows span too little of the object to tell a feature's relief) the
        appearance is voted again after the reseed, so that the finer levels start
        from its matches and see its colours in their context.
    refine_iterations : int
        EM iterations (at most) at the levels finer than ``feature_level``: they
        refine the layout that level drew rather than decide it again (a long EM
        there wore brows that touch the hair down into it).
    context_weights : tuple of float
        At every level but the coarsest, the coarser levels' result as extra guide
        bands, one weight per appearance band (empty or all 0: off; a band weighted 0
        is left out). The query's context is
        its own synthesised coarser levels, an exemplar's its own coarser bands,
        both brought to the level's grid (collapsed, for Laplacian bands, see
        ``appearance_pyramid``). A level's appearance is only its own band, so
        without context a finer level sees nothing of the colours the coarser
        levels chose: it may swap an eye for skin or one example's palette for
        another's wherever the fine band alone fits (the multiresolution
        neighbourhoods of Wei & Levoy 2000 and Hertzmann et al. 2001's image
        analogies).
    context_levels : int, optional
        Give context to the finest this many levels only (None: every level but the
        coarsest).
    context_level_weights : tuple of float
        Per level (finest first), a factor on ``context_weights`` there (empty: 1 at
        every level with context; 0: no context at that level).
    appearance_pyramid : {"laplacian", "gaussian"}
        What the appearance levels are: Laplacian bands (a level's colours are the
        sum of it and every coarser level) or Gaussian levels. Only the context uses it.
    vote : {"mean", "mode"}
        The M-step. ``"mean"`` (the paper): every pixel becomes the Gaussian-weighted
        mean of the estimates of the windows that cover it, the exact minimiser of
        the target for fixed matches, which blurs where the estimates disagree.
        ``"mode"``: every pixel copies the exemplar pixel that most of its windows
        (Gaussian-weighted) agree on, so the output is made of exemplar pixels and
        small features survive; a mode M-step that would raise the target is
        refused (the level then stops), so the target still never increases.
    quantize_features : bool
        Store the PCA window features as 16-bit integers in one unit per level
        (``_FEATURE_RANGE`` steps cover twice the largest value seen in the PCA
        samples) instead of float32: half the engine's largest arrays. The search
        proposes candidates on them; every accepted match is decided on the exact
        float window distance, so the target still never increases.
    """

    patch_sizes: tuple[int, ...] = (7, 11, 9)
    guide_weights: tuple[float, ...] = (1.0,)
    appearance_weights: tuple[float, ...] = (1.0,)
    position_weight: float = 0.0
    pca_fraction: float = 0.2
    pca_max_components: int | None = None
    pca_samples: int = 8000
    backend: str = "patchmatch"
    max_iterations: int = 8
    tolerance: float = 2e-3
    patchmatch_passes: int = 4
    normalize_bands: bool = True
    guide_padding: str = "constant"
    stride: int = 1
    init_from_guide: bool = True
    window_sigma: float = 1.0 / 3.0
    exemplar_costs: tuple[float, ...] = ()
    exemplar_costs_at_finest: bool = True
    vote: str = "mean"
    quantize_features: bool = True
    guide_reseed: float = 0.0
    final_reseed: float = 0.0
    feature_level: int = 0
    refine_iterations: int = 2
    context_weights: tuple[float, ...] = ()
    context_levels: int | None = None
    context_level_weights: tuple[float, ...] = ()
    appearance_pyramid: str = "laplacian"

    def __post_init__(self) -> None:
        if self.vote not in VOTES:
            raise ValueError(f"unknown vote {self.vote!r}; use one of {VOTES}")
        if any(k < 1 or k % 2 == 0 for k in self.patch_sizes):
            raise ValueError(f"patch sizes must be odd and positive, got {self.patch_sizes}")
        if self.backend not in BACKENDS:
            raise ValueError(f"unknown backend {self.backend!r}; use one of {BACKENDS}")
        if not 0 < self.pca_fraction <= 1:
            raise ValueError("pca_fraction must be in (0, 1]")
        if self.guide_padding not in ("constant", "reflect", "edge"):
            raise ValueError("guide_padding must be 'constant', 'reflect' or 'edge'")
        if not 0 <= self.guide_reseed < 1:
            raise ValueError("guide_reseed must be in [0, 1)")
        if not 0 <= self.final_reseed < 1:
            raise ValueError("final_reseed must be in [0, 1)")
        if self.feature_level < 0:
            raise ValueError("feature_level must be >= 0")
        if self.refine_iterations < 1:
            raise ValueError("refine_iterations must be >= 1")
        if self.stride < 1 or self.max_iterations < 0:
            raise ValueError("stride must be at least 1 and max_iterations at least 0")
        if self.appearance_pyramid not in APPEARANCE_PYRAMIDS:
            raise ValueError("appearance_pyramid must be 'laplacian' or 'gaussian'")


@dataclass
class EngineResult:
    """What the engine returns.

    Attributes
    ----------
    appearance : list of ndarray
        Synthesised appearance bands per level, finest first, (H_l, W_l, Ca).
    source : ndarray of int32, shape (H, W, 3)
        Per pixel of the finest level: exemplar index, source y, source x.
    cost : ndarray of float32, shape (H, W)
        Exact window distance of each query window to its match (finest level;
        NaN where no window is centred).
    objective : list of list of float
        Per level (finest first), the target value (mean window distance) after
        each E-step.
    timings : dict
        Seconds per stage.
    backend : str
        The search backend that ran.
    copy_source : ndarray of int32, shape (H, W, 3)
        Per pixel of the finest level: the exemplar pixel most of its windows agree
        on (the weighted mode of their estimates' sources; see ``vote="mode"``),
        for front ends that copy pixels instead of voting them.
    """

    appearance: list[np.ndarray]
    source: np.ndarray
    cost: np.ndarray
    objective: list[list[float]]
    timings: dict[str, float] = field(default_factory=dict)
    backend: str = ""
    copy_source: np.ndarray | None = None


def _trim_heap() -> None:
    """Give the C heap's free pages back to the system (glibc ``malloc_trim``; elsewhere
    nothing). Freed NumPy arrays below glibc's mmap threshold stay in the heap, resident,
    and the next phase's larger arrays are mapped beside them: trimmed between phases,
    the peak is what is alive, not what was once allocated."""
    global _MALLOC_TRIM
    if _MALLOC_TRIM is None:
        _MALLOC_TRIM = False
        if sys.platform.startswith("linux"):
            with contextlib.suppress(OSError, AttributeError):
                _MALLOC_TRIM = ctypes.CDLL("libc.so.6").malloc_trim
    if _MALLOC_TRIM:
        _MALLOC_TRIM(0)


_MALLOC_TRIM = None


class _Timer:
    def __init__(self) -> None:
        self.seconds: dict[str, float] = {}

    def add(self, stage: str, start: float) -> None:
        self.seconds[stage] = self.seconds.get(stage, 0.0) + time.perf_counter() - start


def _gaussian_window(k: int, sigma_fraction: float) -> np.ndarray:
    r = k // 2
    sigma = max(sigma_fraction * k, 0.5)
    offsets = np.arange(-r, r + 1, dtype=np.float64)
    g = np.exp(-(offsets[:, None] ** 2 + offsets[None, :] ** 2) / (2 * sigma**2))
    return (g / g.sum()).astype(np.float32)


def _centroid_frame(mask: np.ndarray | None, shape: tuple[int, int]) -> np.ndarray:
    """(yc, xc, s, s): centroid and RMS radius of the mask (or of the whole frame)."""
    if mask is None:
        mask = np.ones(shape, dtype=bool)
    ys, xs = np.nonzero(mask)
    # One isotropic scale, the object's RMS radius: limbs that move (an arm raised)
    # change the spread along one axis, and must not rescale that axis alone.
    radius = max(float(np.sqrt(ys.var() + xs.var())), 1.0)
    return np.array([ys.mean(), xs.mean(), radius, radius], dtype=np.float64)


def _positions(ys: np.ndarray, xs: np.ndarray, frame: np.ndarray) -> np.ndarray:
    return np.stack([(ys - frame[0]) / frame[2], (xs - frame[1]) / frame[3]], axis=1).astype(
        np.float32
    )


def _pad_into(out: np.ndarray, array: np.ndarray, r: int, mode: str, scale=None) -> None:
    """``np.pad(array * scale, r, mode)`` written into ``out`` ((H + 2r, W + 2r, C), a view
    into a larger array): no padded or scaled temporary of the whole image."""
    h, w = array.shape[:2]
    inner = out[r : r + h, r : r + w]
    if scale is None:
        inner[...] = array
    else:
        np.multiply(array, scale, out=inner)
    if r == 0:
        return
    if mode == "reflect" and (r >= h or r >= w):  # reflected more than once: numpy's rule
        out[...] = np.pad(inner, ((r, r), (r, r), (0, 0)), mode=mode)
        return
    for axis, n in ((0, h), (1, w)):
        lead = out if axis == 0 else out.swapaxes(0, 1)  # pad rows, then columns (all rows)
        if mode == "constant":
            lead[:r] = 0
            lead[r + n :] = 0
        elif mode == "edge":
            lead[:r] = lead[r]
            lead[r + n :] = lead[r + n - 1]
        else:  # reflect (the edge pixel not repeated)
            lead[:r] = lead[2 * r : r : -1]
            lead[r + n :] = lead[r + n - 2 : n - 2 : -1] if n >= 2 else lead[r]


def _pad_index(n: int, r: int, mode: str) -> np.ndarray:
    """Which source row (or column) each of the n + 2r of an axis padded by r on both
    sides shows, by :func:`numpy.pad`'s rule for ``mode`` (-1: the constant 0)."""
    index = np.arange(n, dtype=np.int64)
    if mode == "constant":
        return np.pad(index, r, mode="constant", constant_values=-1)
    return np.pad(index, r, mode=mode)


def _pad_crop_into(out, array, r, mode, rows: slice, cols: slice, scale=None) -> None:
    """``np.pad(array * scale, r, mode)[rows, cols]`` written into ``out`` (a view of a
    larger array): the crop alone, without the padded whole. The padding modes are
    separable (numpy pads axis by axis), so a crop is a gather of source rows and
    columns; the products are the same float32 ones as of the padded whole."""
    h, w = array.shape[:2]
    if rows == slice(0, h + 2 * r) and cols == slice(0, w + 2 * r):  # the whole: in place
        _pad_into(out, array, r, mode, scale)
        return
    row_index = _pad_index(h, r, mode)[rows]
    col_index = _pad_index(w, r, mode)[cols]
    inside_rows, inside_cols = row_index >= 0, col_index >= 0  # all but constant padding
    block = array[row_index[inside_rows][:, None], col_index[inside_cols][None, :]]
    if scale is not None:
        np.multiply(block, scale, out=block)
    if inside_rows.all() and inside_cols.all():
        out[...] = block
        return
    out[...] = 0
    out[np.ix_(inside_rows, inside_cols)] = block


def _box(valid: np.ndarray) -> tuple[int, int, int, int]:
    """Rows y0:y1 and columns x0:x1 of the bounding box of a non-empty boolean image."""
    rows, cols = np.flatnonzero(valid.any(axis=1)), np.flatnonzero(valid.any(axis=0))
    return int(rows[0]), int(rows[-1]) + 1, int(cols[0]), int(cols[-1]) + 1


def _channels(array: np.ndarray, channels: np.ndarray) -> np.ndarray:
    """``array[..., channels]`` without a copy when ``channels`` are all of them, in order."""
    if np.array_equal(channels, np.arange(array.shape[-1])):
        return array
    return array[..., channels]


def _fit_pca(
    samples: np.ndarray, n_keep: int, rng: np.random.Generator, overwrite: bool = False
) -> tuple[np.ndarray, np.ndarray]:
    """Mean (D,) and the n_keep leading principal directions (D, n_keep) of the rows
    (``overwrite``: float32 ``samples`` are centred in place, not copied)."""
    mean = samples.mean(axis=0)
    if overwrite and samples.dtype == np.float32:
        centered = np.subtract(samples, mean, out=samples)
    else:
        centered = (samples - mean).astype(np.float32, copy=False)
    dim = centered.shape[1]
    if dim <= 1024 or 4 * n_keep > dim:
        cov = (centered.T @ centered).astype(np.float64)
        eigvals, eigvecs = np.linalg.eigh(cov)
        basis = eigvecs[:, ::-1][:, :n_keep]
    else:  # randomised range finder (Halko et al.): the covariance would be too large
        omega = rng.standard_normal((dim, n_keep + 10)).astype(np.float32)
        y = centered @ omega
        for _ in range(2):
            y, _ = np.linalg.qr(y)
            y = centered @ (centered.T @ y)
        q, _ = np.linalg.qr(y)
        _, _, vt = np.linalg.svd(q.T @ centered, full_matrices=False)
        basis = vt[:n_keep].T
    return mean.astype(np.float32), np.ascontiguousarray(basis, dtype=np.float32)


class _Windows:
    """Flattened k x k windows of some channels of a band stack, optionally scaled.

    ``view`` is a sliding-window view, (..., C, k, k); ``channels`` a slice (free on
    the view) or an index array (applied after the gather), None for all; ``scale``
    one factor per selected channel (the exemplars' appearance is stored unscaled,
    once, and scaled per block of windows: the same float32 products as a scaled
    copy, without the copy).
    """

    def __init__(self, view: np.ndarray, channels=None, scale: np.ndarray | None = None) -> None:
        self.view = view
        self.channels = channels
        k = view.shape[-1]
        self.scale = None if scale is None else np.repeat(scale.astype(np.float32), k * k)

    @property
    def width(self) -> int:
        """Values per window (selected channels times k^2)."""
        view = self.view
        if isinstance(self.channels, slice):
            return view[..., self.channels, :, :].shape[-3] * view.shape[-1] ** 2
        n = view.shape[-3] if self.channels is None else len(self.channels)
        return n * view.shape[-1] ** 2

    def __call__(self, index: tuple[np.ndarray, ...], out: np.ndarray | None = None) -> np.ndarray:
        """The (N, width) windows at ``index``, into the first N rows of ``out`` if given
        (a buffer reused from block to block)."""
        view = self.view
        if isinstance(self.channels, slice):
            view = view[..., self.channels, :, :]
        channels = range(view.shape[-3])
        if self.channels is not None and not isinstance(self.channels, slice):
            channels = self.channels
        # Gathered one channel at a time into the (N, C, k, k) block: the gather of all
        # channels at once comes out in the view's memory order (not C-contiguous), and
        # flattening it copied the whole block a second time.
        k, n = view.shape[-1], index[0].shape[0]
        if out is None:
            block = np.empty((n, len(channels), k, k), dtype=view.dtype)
        else:
            block = out[:n].reshape(n, len(channels), k, k)
        # In runs of _GATHER_ROWS windows: each channel's gather makes a temporary, and
        # small ones are reused from the heap instead of being mapped and faulted in anew.
        for start in range(0, n, _GATHER_ROWS):
            sub = tuple(i[start : start + _GATHER_ROWS] for i in index)
            rows = block[start : start + _GATHER_ROWS]
            for i, channel in enumerate(channels):
                rows[:, i] = view[..., channel, :, :][sub]
        block = block.reshape(n, -1)
        if self.scale is not None:
            block *= self.scale
        return block


class _Projection:
    """Weighted window -> PCA coordinates, for one part (guide or appearance) of the bands."""

    def __init__(self, n_channels: int, window: np.ndarray) -> None:
        self.n_channels = n_channels
        # Window order of sliding_window_view: (channel, ky, kx).
        self.sqrt_weights = np.tile(np.sqrt(window).ravel(), n_channels).astype(np.float32)
        self.matrix: np.ndarray | None = None
        self.offset: np.ndarray | None = None

    @property
    def n_components(self) -> int:
        return 0 if self.matrix is None else self.matrix.shape[1]

    def fit(self, samples: np.ndarray, fraction: float, cap: int | None, rng) -> None:
        """Learn the projection from window ``samples`` (float32, overwritten: weighted
        and centred in place, no copies of the samples)."""
        weighted = np.multiply(samples, self.sqrt_weights, out=samples)
        n_keep = max(1, int(round(fraction * weighted.shape[1])))
        if cap is not None:
            n_keep = min(n_keep, cap)
        mean, basis = _fit_pca(weighted, n_keep, rng, overwrite=True)
        self.matrix = np.ascontiguousarray(self.sqrt_weights[:, None] * basis)
        self.offset = mean @ basis

    def project(
        self,
        windows: _Windows,
        index: tuple[np.ndarray, ...],
        out: np.ndarray | None = None,
        inverse_unit: float | None = None,
    ) -> np.ndarray:
        """PCA coordinates of the windows at ``index`` (into ``out``, (N, n_components),
        which may be a column slice of a larger array), in blocks of windows; with
        ``inverse_unit``, quantized (see :func:`_store`)."""
        n = index[0].shape[0]
        if out is None:
            out = np.empty((n, self.n_components), dtype=np.float32)
        # One buffer for the windows and one for their product, reused by every block (not
        # a fresh large array per block: each would be mapped and faulted in anew).
        rows = min(_CHUNK, n)
        gathered = np.empty((rows, windows.width), dtype=np.float32)
        product = np.empty((rows, self.n_components), dtype=np.float32)
        for start in range(0, n, _CHUNK):
            sub = tuple(i[start : start + _CHUNK] for i in index)
            m = sub[0].shape[0]
            values = np.matmul(windows(sub, gathered), self.matrix, out=product[:m])
            np.subtract(values, self.offset, out=values)
            _store(out[start : start + m], values, inverse_unit)
        return out


def _store(out: np.ndarray, values: np.ndarray, inverse_unit: float | None) -> None:
    """``out[...] = values``, or the nearest integer multiples of the unit, clipped to
    +-_FEATURE_RANGE, when ``inverse_unit`` is given (``values`` is overwritten)."""
    if inverse_unit is None:
        out[...] = values
        return
    np.multiply(values, np.float32(inverse_unit), out=values)
    np.rint(values, out=values)
    np.clip(values, -_FEATURE_RANGE, _FEATURE_RANGE, out=values)
    out[...] = values


class _LevelSolver:
    """Everything the EM iterations of one level need, built once for the level."""

    def __init__(
        self,
        query: Mapping,
        exemplars: Sequence[Mapping],
        k: int,
        params: EngineParams,
        rng: np.random.Generator,
        timer: _Timer,
        prepare: bool = True,
        context: tuple[np.ndarray, list[np.ndarray]] | None = None,
        release=None,
    ) -> None:
        """Pack the bands of ``query`` and ``exemplars`` (nothing of the mappings is kept),
        then, unless ``prepare`` is False, learn the PCA and make the features
        (:meth:`prepare`): with False the caller may free the mappings first.

        ``context``: (query's, exemplars') extra guide bands, (H, W, Cc) each, that
        follow the mappings' own guide bands (``params.guide_weights`` covers both):
        packed from where they are, not concatenated into a copy of every guide.
        ``release``: called with an exemplar's index once its bands are packed, so that
        the caller may free its mapping (and context) before the next one is packed;
        ``exemplars`` (a list) then loses that entry too.
        """
        start = time.perf_counter()
        self.params = params
        self.r = r = k // 2
        self.window = _gaussian_window(k, params.window_sigma)
        self.timer = timer
        self.chosen: np.ndarray | None = None  # sources the mode vote copied
        n_appearance = exemplars[0].appearance.shape[2]
        guide_w = np.asarray(params.guide_weights, dtype=np.float32)
        appearance_w = np.asarray(params.appearance_weights, dtype=np.float32)
        self.guide_active = np.flatnonzero(guide_w != 0)
        self.appearance_active = np.flatnonzero(appearance_w != 0)
        n_ga, n_aa = len(self.guide_active), len(self.appearance_active)
        self.n_guide_active = n_ga
        query_context, exemplar_context = context or (None, [None] * len(exemplars))
        n_own = query.guide.shape[2]  # the mappings' own guide bands; context ones after

        # Band scales: weight per standard deviation over the exemplars' masks.
        guide_scale = guide_w[self.guide_active]
        appearance_scale = appearance_w[self.appearance_active]
        if params.normalize_bands:
            guide_scale = guide_scale / self._band_std(
                exemplars, "guide", self.guide_active, exemplar_context, n_own
            )
            appearance_scale = appearance_scale / self._band_std(
                exemplars, "appearance", self.appearance_active
            )
        self.appearance_scale = appearance_scale.astype(np.float32)

        # Exemplars: padded and packed into one array each (zero beyond each one's size).
        # Index arrays are int32 (half the memory of int64; sizes stay far below 2^31).
        heights = [e.shape[0] for e in exemplars]
        widths = [e.shape[1] for e in exemplars]
        n_ex = len(exemplars)
        self.exemplar_shape = np.array([heights, widths], dtype=np.int64).T.copy()
        # Candidates: window centres in the (dilated) mask. Only their windows are ever
        # read, so the bands are packed for the box around them (an object often fills
        # a third of its frame): band_origin is the box's top-left in frame coordinates,
        # band_y, band_x a candidate's window's top-left in the packed bands.
        self.exemplar_valid = [self._region(ex.mask, ex.shape, r) for ex in exemplars]
        boxes = [_box(valid) for valid in self.exemplar_valid]
        self.band_origin = np.array([box[::2] for box in boxes], dtype=np.int32).reshape(-1, 2)
        hp = max(y1 - y0 for y0, y1, _, _ in boxes) + 2 * r
        wp = max(x1 - x0 for _, _, x0, x1 in boxes) + 2 * r
        # Guide bands scaled; appearance bands once, unscaled (the matched ones are scaled
        # where they are read: kernels and feature blocks).
        self.exemplar_guide = np.zeros((n_ex, hp, wp, n_ga), dtype=np.float32)
        self.exemplar_appearance = np.zeros((n_ex, hp, wp, n_appearance), dtype=np.float32)
        cand_e, cand_y, cand_x, positions = [], [], [], []
        self.exemplar_lookup = np.full((n_ex, max(heights), max(widths)), -1, dtype=np.int32)
        n_cand = 0
        for e in range(n_ex):
            ex = exemplars[e]
            h, w = ex.shape
            y0, y1, x0, x1 = boxes[e]
            # The box's rows and columns of the padded frame (padded coordinates).
            rows, cols = slice(y0, y1 + 2 * r), slice(x0, x1 + 2 * r)
            crop = (slice(0, y1 - y0 + 2 * r), slice(0, x1 - x0 + 2 * r))
            self._pad_guide(
                self.exemplar_guide[e][crop],
                ex.guide,
                exemplar_context[e],
                r,
                guide_scale,
                rows,
                cols,
            )
            _pad_crop_into(
                self.exemplar_appearance[e][crop], ex.appearance, r, "reflect", rows, cols
            )
            ys, xs = np.nonzero(self.exemplar_valid[e])
            self.exemplar_lookup[e, ys, xs] = np.arange(n_cand, n_cand + len(ys))
            n_cand += len(ys)
            cand_e.append(np.full(len(ys), e, dtype=np.int32))
            cand_y.append(ys.astype(np.int32))
            cand_x.append(xs.astype(np.int32))
            positions.append(_positions(ys, xs, _centroid_frame(ex.mask, (h, w))))
            del ex
            if release is not None:  # packed: the caller's mapping may go now
                exemplars[e] = None
                release(e)
        self.cand_e = np.concatenate(cand_e)
        self.cand_y = np.concatenate(cand_y)
        self.cand_x = np.concatenate(cand_x)
        self.band_y = self.cand_y - self.band_origin[self.cand_e, 0]
        self.band_x = self.cand_x - self.band_origin[self.cand_e, 1]
        self.cand_position = np.concatenate(positions)
        costs = np.zeros(n_ex, dtype=np.float32)
        if params.exemplar_costs:
            if len(params.exemplar_costs) != n_ex:
                raise ValueError(f"{n_ex} exemplars need as many exemplar_costs")
            costs[:] = params.exemplar_costs
        if np.any(costs < 0):
            raise ValueError("exemplar_costs must not be negative")
        self.cand_bias = costs[self.cand_e]

        # Query: centres inside the (dilated) mask on the stride grid.
        self.query_shape = query.shape
        h, w = query.shape
        centres = self._region(query.mask, (h, w), r)
        if params.stride > 1:
            grid = np.zeros((h, w), dtype=bool)
            grid[:: params.stride, :: params.stride] = True
            # The last row and column too, so that every pixel is covered by a window.
            grid[h - 1, :: params.stride] = grid[:: params.stride, w - 1] = True
            grid[h - 1, w - 1] = True
            centres &= grid
        self.query_y, self.query_x = (a.astype(np.int32) for a in np.nonzero(centres))
        self.query_lookup = np.full((h, w), -1, dtype=np.int32)
        self.query_lookup[self.query_y, self.query_x] = np.arange(len(self.query_y))
        self.query_position = _positions(
            self.query_y, self.query_x, _centroid_frame(query.mask, (h, w))
        )
        # The query's matched bands, like the exemplars', for the box around its window
        # centres only: query_band_y, query_band_x are a centre's window's top-left there,
        # query_crop the box's rows and columns of the padded frame.
        y0, y1, x0, x1 = _box(centres)
        self.query_band_y, self.query_band_x = self.query_y - y0, self.query_x - x0
        self.query_crop = (slice(y0, y1 + 2 * r), slice(x0, x1 + 2 * r))
        self.query_active = np.zeros(
            (y1 - y0 + 2 * r, x1 - x0 + 2 * r, n_ga + n_aa), dtype=np.float32
        )
        self._pad_guide(
            self.query_active[..., :n_ga],
            query.guide,
            query_context,
            r,
            guide_scale,
            *self.query_crop,
        )
        timer.add("setup", start)
        if prepare:
            self.prepare(rng)

    def prepare(self, rng: np.random.Generator) -> None:
        """PCA learned on exemplar windows, and the features of candidates and query
        windows: from the packed bands alone."""
        k, timer, params = 2 * self.r + 1, self.timer, self.params
        n_ga, n_aa = self.n_guide_active, len(self.appearance_active)
        n_appearance = self.exemplar_appearance.shape[-1]
        h = self.query_shape[0]

        # PCA, learned on exemplar windows, separately for guide and appearance.
        start = time.perf_counter()
        all_appearance = np.array_equal(self.appearance_active, np.arange(n_appearance))
        self.exemplar_windows = (
            _Windows(sliding_window_view(self.exemplar_guide, (k, k), axis=(1, 2))),
            _Windows(
                sliding_window_view(self.exemplar_appearance, (k, k), axis=(1, 2)),
                None if all_appearance else self.appearance_active,
                self.appearance_scale,
            ),
        )
        self.guide_projection = _Projection(n_ga, self.window)
        self.appearance_projection = _Projection(n_aa, self.window)
        n_samples = min(params.pca_samples, len(self.cand_e))
        pick = np.sort(rng.choice(len(self.cand_e), size=n_samples, replace=False))
        sample_index = (self.cand_e[pick], self.band_y[pick], self.band_x[pick])
        projections = (self.guide_projection, self.appearance_projection)
        largest = 0.0
        for projection, windows in zip(projections, self.exemplar_windows, strict=True):
            if projection.n_channels:
                # The samples are consumed by the fit (weighted and centred in place).
                projection.fit(
                    windows(sample_index), params.pca_fraction, params.pca_max_components, rng
                )
                if params.quantize_features:
                    largest = max(
                        largest, float(np.abs(projection.project(windows, sample_index)).max())
                    )
        if params.quantize_features:
            position = np.float32(params.position_weight)
            for values in (self.cand_position, self.query_position):
                largest = max(largest, float(np.abs(values).max(initial=0.0)) * position)
            largest = max(largest, float(np.sqrt(self.cand_bias.max(initial=0.0))), 1e-30)
            # Features in steps of one unit, to _FEATURE_MARGIN times the largest value seen.
            self.inverse_unit: float | None = _FEATURE_RANGE / (_FEATURE_MARGIN * largest)
        else:
            self.inverse_unit = None
        timer.add("pca", start)

        # Features: [guide PCA | weighted position | exemplar cost | appearance PCA].
        start = time.perf_counter()
        index = (self.cand_e, self.band_y, self.band_x)
        # [guide PCA | position (2) | exemplar cost (1) | appearance PCA]
        self.n_init_dims = self.guide_projection.n_components + 3
        self.candidate_features = self._features(
            self.exemplar_windows, index, self.cand_position, np.sqrt(self.cand_bias)
        )
        query_view = sliding_window_view(self.query_active, (k, k), axis=(0, 1))
        self.query_windows = (
            _Windows(query_view, slice(0, n_ga)),
            _Windows(query_view, slice(n_ga, n_ga + n_aa)),
        )
        self.query_features = self._features(
            self.query_windows, (self.query_band_y, self.query_band_x), self.query_position, 0.0
        )
        ys = self.query_y
        n_bands = int(np.clip(h // _BAND_ROWS, 1, _MAX_BANDS))
        row_edges = np.linspace(0, h, n_bands + 1).astype(np.int64)
        self.band_starts = np.searchsorted(ys, row_edges, side="left").astype(np.int64)
        timer.add("features", start)
        self.indexes: dict[str, object] = {}

    def _pad_guide(self, out, guide, context, r, scale, rows, cols) -> None:
        """The active guide channels, of the mapping's own bands then of the context
        bands, scaled and padded, the crop ``rows``, ``cols`` of the padded frame into
        ``out`` (the channels written part by part: the same float32 products as of
        one concatenated guide)."""
        n = 0
        for array, channels in _guide_parts(guide, context, self.guide_active):
            m = n + len(channels)
            _pad_crop_into(
                out[..., n:m],
                _channels(array, channels),
                r,
                self.params.guide_padding,
                rows,
                cols,
                scale[n:m],
            )
            n = m

    @staticmethod
    def _band_std(
        exemplars: Sequence[Mapping],
        part: str,
        channels: np.ndarray,
        context: Sequence[np.ndarray | None] | None = None,
        n_own: int | None = None,
    ) -> np.ndarray:
        if len(channels) == 0:
            return np.ones(0, dtype=np.float32)
        values = []
        for e, ex in enumerate(exemplars):
            if part == "guide":  # own bands, then context bands: one (N, C) array
                extra = None if context is None else context[e]
                parts = _guide_parts(ex.guide, extra, channels, n_own)
                picked = [array[..., c] for array, c in parts]
                bands = picked[0] if len(picked) == 1 else np.concatenate(picked, axis=2)
            else:
                bands = getattr(ex, part)[..., channels]
            values.append(
                bands[ex.mask] if ex.mask is not None else bands.reshape(-1, len(channels))
            )
        stacked = np.concatenate(values, axis=0)
        std = stacked.std(axis=0)
        floor = max(float(std.max()), 1e-12) * 1e-3
        return np.maximum(std, floor).astype(np.float32)

    @staticmethod
    def _region(mask: np.ndarray | None, shape: tuple[int, int], r: int) -> np.ndarray:
        if mask is None:
            return np.ones(shape, dtype=bool)
        return ndimage.binary_dilation(mask, iterations=max(r, 1))

    def _features(self, windows, index, position, bias) -> np.ndarray:
        """(N, D) features [guide PCA | weighted position | sqrt of the exemplar cost
        (candidates; 0 for the query) | appearance PCA], made in blocks of windows and
        stored as float32 or quantized (int16)."""
        n_guide = self.guide_projection.n_components
        n_dims = self.n_init_dims + self.appearance_projection.n_components
        dtype = np.float32 if self.inverse_unit is None else np.int16
        out = np.empty((len(position), n_dims), dtype=dtype)
        block = np.empty((min(_CHUNK, len(position)), n_dims), dtype=np.float32)
        weight = np.float32(self.params.position_weight)
        for start in range(0, len(position), _CHUNK):
            stop = min(start + _CHUNK, len(position))
            sub = tuple(i[start:stop] for i in index)
            values = block[: stop - start]
            if n_guide:
                self.guide_projection.project(windows[0], sub, values[:, :n_guide])
            values[:, n_guide : n_guide + 2] = position[start:stop] * weight
            values[:, n_guide + 2] = bias if np.ndim(bias) == 0 else bias[start:stop]
            if self.appearance_projection.n_components:
                self.appearance_projection.project(windows[1], sub, values[:, self.n_init_dims :])
            _store(out[start:stop], values, self.inverse_unit)
        return out

    # -- the two steps ---------------------------------------------------------

    def set_appearance(self, appearance_padded: np.ndarray, project: bool = True) -> None:
        """Install the current appearance estimate; refresh the query's PCA features
        too unless ``project`` is False (exact costs need only the bands)."""
        start = time.perf_counter()
        n_ga = self.n_guide_active
        # No temporaries: the product is written into the query's band stack.
        np.multiply(
            _channels(appearance_padded[self.query_crop], self.appearance_active),
            self.appearance_scale,
            out=self.query_active[..., n_ga:],
        )
        if project and self.appearance_projection.n_components:
            self.appearance_projection.project(
                self.query_windows[1],
                (self.query_band_y, self.query_band_x),
                self.query_features[:, self.n_init_dims :],
                self.inverse_unit,
            )
        self.timer.add("features", start)

    def costs(self, matches: np.ndarray, subset: np.ndarray | None = None) -> np.ndarray:
        """Exact window distances of query centres (all, or ``subset``) to ``matches``."""
        start = time.perf_counter()
        if subset is None:
            centres_y, centres_x = self.query_band_y, self.query_band_x
            positions = self.query_position
        else:
            matches = matches[subset]
            centres_y, centres_x = self.query_band_y[subset], self.query_band_x[subset]
            positions = self.query_position[subset]
        out = _kernels.window_costs(
            self.query_active,
            self.exemplar_guide,
            self.exemplar_appearance,
            self.appearance_active,
            self.appearance_scale,
            self.window,
            centres_y,
            centres_x,
            self.cand_e,
            self.band_y,
            self.band_x,
            np.ascontiguousarray(matches),
            positions,
            self.cand_position,
            np.float32(self.params.position_weight**2),
            self.cand_bias,
        )
        self.timer.add("costs", start)
        return out

    def vote(
        self, matches: np.ndarray, appearance_padded: np.ndarray, kind: str | None = None
    ) -> np.ndarray:
        """M-step into ``appearance_padded`` (in place, also returned); ``kind`` overrides
        ``params.vote`` ("mode" also records the copied sources for :meth:`dense_source`)."""
        start = time.perf_counter()
        windows = (
            self.exemplar_appearance,
            self.window,
            self.query_lookup,
            self.cand_e,
            self.band_y,
            self.band_x,
            matches,
        )
        if (kind or self.params.vote) == "mode":
            self.chosen = np.empty(appearance_padded.shape[:2] + (3,), dtype=np.int32)
            _kernels.vote_mode(*windows, appearance_padded, self.chosen)
        else:
            _kernels.vote(*windows, appearance_padded)
        self.timer.add("vote", start)
        return appearance_padded

    def search(self, matches: np.ndarray | None, init: bool, seed: int, rng) -> np.ndarray:
        """E-step search: new candidate matches (PCA space) for every query centre."""
        ndims = self.n_init_dims if init else self.candidate_features.shape[1]
        backend = self.params.backend
        if backend == "patchmatch":
            start = time.perf_counter()
            passes = self.params.patchmatch_passes
            if matches is None:
                n_query, n_cand = len(self.query_y), len(self.cand_e)
                if n_query * n_cand * ndims <= _EXACT_START_FLOPS:
                    # A small (coarsest) level: an exact global start costs little.
                    data = self.candidate_features[:, :ndims].astype(np.float32)
                    start_index = make_index("exact", data)
                    matches, _ = start_index.query(
                        self.query_features[:, :ndims].astype(np.float32)
                    )
                else:
                    matches = rng.integers(0, n_cand, size=n_query)
                    passes *= 2
            new = np.ascontiguousarray(matches, dtype=np.int64).copy()
            distances = _kernels.feature_distances(
                self.query_features, self.candidate_features, new, ndims
            )
            _kernels.patchmatch(
                self.query_features,
                self.candidate_features,
                ndims,
                self.query_y,
                self.query_x,
                self.query_lookup,
                self.cand_e,
                self.cand_y,
                self.cand_x,
                self.exemplar_lookup,
                self.exemplar_shape,
                self.band_starts,
                new,
                distances,
                passes,
                self.params.stride,
                seed,
            )
            self.timer.add("search", start)
            return new
        key = "init" if init else "full"
        if key not in self.indexes:
            start = time.perf_counter()
            data = np.ascontiguousarray(self.candidate_features[:, :ndims], dtype=np.float32)
            self.indexes[key] = make_index(backend, data, seed=seed)
            self.timer.add("index", start)
        start = time.perf_counter()
        queries = np.ascontiguousarray(self.query_features[:, :ndims], dtype=np.float32)
        new, _ = self.indexes[key].query(queries)
        self.timer.add("search", start)
        return new.astype(np.int64)

    def release_search(self) -> None:
        """Free what only the E-step and the exact costs need (features, guide and query
        bands, exemplar lookups): the votes and the dense source maps do not."""
        for name in (
            "candidate_features",
            "query_features",
            "exemplar_guide",
            "exemplar_windows",
            "query_active",
            "query_windows",
            "exemplar_lookup",
            "exemplar_valid",
            "cand_position",
            "indexes",
        ):
            setattr(self, name, None)

    def reseed(
        self,
        matches: np.ndarray,
        ratio: float,
        seed: int,
        rng,
        worst: float = RESEED_WORST,
        keep_detail: bool = False,
    ) -> np.ndarray:
        """Propagated matches, some replaced by matches on guide and position only.

        A replacement is taken where the propagated match is among the
        ``worst`` share of worst fits of the guide and the guide-only match fits it
        in less than ``ratio`` of that distance: relief that the coarser levels
        could not resolve (a small bulging eye) then gets its own match instead of
        the coarser level's appearance there. With ``keep_detail`` a replacement must
        also carry at least the appearance detail of the match it replaces (the
        energy of its window's appearance features): relief the depth marks only
        vaguely (a brow ridge) keeps the brow the EM drew rather than a plain patch
        that fits the ridge a little better.
        """
        guided = self.search(matches, init=True, seed=seed, rng=rng)
        n = self.n_init_dims
        matches = np.ascontiguousarray(matches, dtype=np.int64)
        fit = _kernels.feature_distances(self.query_features, self.candidate_features, matches, n)
        fit_guided = _kernels.feature_distances(
            self.query_features, self.candidate_features, guided, n
        )
        take = (fit > np.quantile(fit, 1.0 - worst)) & (fit_guided < ratio * fit)
        if keep_detail:
            take &= self._appearance_energy(guided) >= self._appearance_energy(matches)
        log.info("reseed: %d of %d matches taken from the guide", int(take.sum()), len(take))
        return np.where(take, guided, matches)

    def _appearance_energy(self, matches: np.ndarray) -> np.ndarray:
        """Squared norm of each matched window's appearance features (its detail).

        The features are PCA coefficients about the examples' mean window: of Laplacian
        bands this is the window's detail; of plain colour levels (Gaussian) it is how
        far the window stands out from the mean window in colour and detail, which
        still ranks an eye or a brow above plain skin."""
        features = self.candidate_features[matches, self.n_init_dims :].astype(np.float64)
        return np.einsum("ij,ij->i", features, features)

    def propagate(self, coarse_source: np.ndarray) -> np.ndarray:
        """Initial matches from the coarser level's dense source map (coordinates x2)."""
        ys, xs = self.query_y, self.query_x
        src = coarse_source[
            np.minimum(ys // 2, coarse_source.shape[0] - 1),
            np.minimum(xs // 2, coarse_source.shape[1] - 1),
        ]
        e = src[:, 0]
        sy = np.minimum(2 * src[:, 1] + ys % 2, self.exemplar_shape[e, 0] - 1)
        sx = np.minimum(2 * src[:, 2] + xs % 2, self.exemplar_shape[e, 1] - 1)
        matches = np.empty(len(ys), dtype=np.int64)
        for ex, valid in enumerate(self.exemplar_valid):
            # Nearest candidate of every exemplar pixel: snaps propagated coordinates (made
            # here, used once: not kept through the level's iterations).
            ny, nx = ndimage.distance_transform_edt(
                ~valid, return_distances=False, return_indices=True
            )
            sel = e == ex
            at = (sy[sel], sx[sel])  # the nearest candidate read where it is needed only
            matches[sel] = self.exemplar_lookup[ex, ny[at], nx[at]]
            del ny, nx
        return matches

    def dense_source(self, matches: np.ndarray, copied: bool | None = None) -> np.ndarray:
        """(H, W, 3) exemplar, y, x for every pixel: the pixel it copied (after a mode vote;
        ``copied`` overrides ``params.vote``), else its position in the match of its
        nearest window centre."""
        h, w = self.query_shape
        ny, nx = ndimage.distance_transform_edt(
            self.query_lookup < 0, return_distances=False, return_indices=True
        )
        if copied is None:
            copied = self.params.vote == "mode"
        copied_by_mode = copied and self.chosen is not None
        r = self.r
        out = np.empty((h, w, 3), dtype=np.int32)
        xx = np.arange(w)[None, :]
        for y0 in range(0, h, _SOURCE_ROWS):  # in blocks of rows: int64 temporaries stay small
            y1 = min(h, y0 + _SOURCE_ROWS)
            block_ny, block_nx = ny[y0:y1], nx[y0:y1]
            c = matches[self.query_lookup[block_ny, block_nx]]
            e = self.cand_e[c]
            sy = self.cand_y[c] + (np.arange(y0, y1)[:, None] - block_ny)
            sx = self.cand_x[c] + (xx - block_nx)
            if copied_by_mode:
                chosen = self.chosen[r + y0 : r + y1, r : r + w]
                copied = chosen[..., 0] >= 0
                e = np.where(copied, chosen[..., 0], e)
                # The mode vote records padded coordinates in the packed bands.
                origin = self.band_origin[e] - r
                sy = np.where(copied, chosen[..., 1] + origin[..., 0], sy)
                sx = np.where(copied, chosen[..., 2] + origin[..., 1], sx)
            out[y0:y1, :, 0] = e
            out[y0:y1, :, 1] = np.clip(sy, 0, self.exemplar_shape[e, 0] - 1)
            out[y0:y1, :, 2] = np.clip(sx, 0, self.exemplar_shape[e, 1] - 1)
        return out


def _guide_parts(guide, context, active, n_own=None):
    """The ``active`` guide channels as (array, channel indices) parts: of the mapping's
    own ``guide`` bands (the first ``n_own``, default all of them), then of the
    ``context`` bands (None: none)."""
    n_own = guide.shape[2] if n_own is None else n_own
    parts = [(guide, active[active < n_own])]
    if context is not None:
        parts.append((context, active[active >= n_own] - n_own))
    return [(array, channels) for array, channels in parts if len(channels)]


def _coarse_colours(coarser: np.ndarray | None, band: np.ndarray, kind: str) -> np.ndarray:
    """A level's colours from its band and the coarser level's colours (running collapse)."""
    if kind == "gaussian" or coarser is None:
        return np.asarray(band, dtype=np.float32)
    return collapse_laplacian([band, coarser])  # one step of the collapse


def _context(mapping: Mapping, coarser_colours: np.ndarray) -> np.ndarray:
    """The coarser level's colours brought to a level's grid: its context guide bands,
    (H, W, Cc) float32."""
    context = np.asarray(expand(coarser_colours, mapping.shape), dtype=np.float32)
    return context if context.ndim == 3 else context[..., None]


def _validate(query_levels, exemplar_levels, params) -> None:
    n_levels = len(query_levels)
    if n_levels == 0:
        raise ValueError("no query levels")
    if len(exemplar_levels) == 0:
        raise ValueError("at least one exemplar is needed")
    if len(params.patch_sizes) < n_levels:
        raise ValueError(f"{n_levels} levels need {n_levels} patch sizes, got {params.patch_sizes}")
    n_guide = query_levels[0].guide.shape[2]
    if len(params.guide_weights) != n_guide:
        raise ValueError(f"{n_guide} guide bands need as many guide weights")
    for i, levels in enumerate(exemplar_levels):
        if len(levels) != n_levels:
            raise ValueError(f"exemplar {i} has {len(levels)} levels, the query {n_levels}")
        for level, ex in enumerate(levels):
            if ex.appearance is None:
                raise ValueError(f"exemplar {i} level {level} has no appearance")
            if ex.guide.shape[2] != n_guide:
                raise ValueError(
                    f"exemplar {i} has {ex.guide.shape[2]} guide bands, query {n_guide}"
                )
            if ex.appearance.shape[2] != exemplar_levels[0][level].appearance.shape[2]:
                raise ValueError(f"exemplar {i} differs from exemplar 0 in appearance bands")
    n_appearance = exemplar_levels[0][0].appearance.shape[2]
    if len(params.appearance_weights) != n_appearance:
        raise ValueError(f"{n_appearance} appearance bands need as many appearance weights")
    if params.context_weights and len(params.context_weights) != n_appearance:
        raise ValueError(f"{n_appearance} appearance bands need as many context weights")
    level_weights = params.context_level_weights
    if level_weights and (len(level_weights) != n_levels or min(level_weights) < 0):
        raise ValueError(f"{n_levels} levels need as many non-negative context level weights")
    for level in range(1, n_levels):
        fine, coarse = query_levels[level - 1].shape, query_levels[level].shape
        if coarse != ((fine[0] + 1) // 2, (fine[1] + 1) // 2):
            raise ValueError(f"query level {level} of shape {coarse} is not half of {fine}")


def synthesize(
    query_levels: Sequence[Mapping],
    exemplar_levels: Sequence[Sequence[Mapping]],
    params: EngineParams | None = None,
    *,
    seed: int = 0,
    quiet: bool = True,
) -> EngineResult:
    """Synthesise the query's appearance from exemplars, coarse to fine, by hard EM.

    Parameters
    ----------
    query_levels : sequence of Mapping
        Query pyramid, finest first; appearance is ignored.
    exemplar_levels : sequence of sequence of Mapping
        One pyramid (finest first, same level count) per exemplar. A pyramid given as
        :class:`ReleasableLevels` is handed over: each level is dropped from it once its
        bands are packed (a front end's pyramids then do not add to the peak memory).
    params : EngineParams, optional
    seed : int
        Seeds every random choice; the same seed gives the same bytes.
    quiet : bool
        No progress bar.

    Returns
    -------
    EngineResult
    """
    params = params or EngineParams()
    _validate(query_levels, exemplar_levels, params)
    # One BLAS thread: the numba kernels own the cores, and a multithreaded
    # OpenBLAS on a busy machine spins (a 363x363 eigh measured 300x slower).
    _trim_heap()  # the front end's temporaries: freed, not yet given back
    with threadpool_limits(limits=1, user_api="blas"):
        return _synthesize(query_levels, exemplar_levels, params, seed, quiet)


def _synthesize(query_levels, exemplar_levels, params, seed, quiet) -> EngineResult:
    rng = np.random.default_rng(seed)
    timer = _Timer()
    n_levels = len(query_levels)
    n_appearance = exemplar_levels[0][0].appearance.shape[2]
    log.info("search backend: %s", params.backend)
    appearance_levels: list[np.ndarray] = [None] * n_levels  # type: ignore[list-item]
    objective: list[list[float]] = [[] for _ in range(n_levels)]
    coarse_source = None
    solver = None
    matches = None
    # Only the bands with a context weight are collapsed and matched (luma alone by
    # default in colorize: one band of three).
    context_bands = np.flatnonzero(np.asarray(params.context_weights, dtype=np.float64))
    context_weights = tuple(float(params.context_weights[b]) for b in context_bands)
    # Levels below context_from get the coarser levels' colours as context.
    context_from = 0
    if context_weights:
        limit = n_levels - 1 if params.context_levels is None else params.context_levels
        context_from = min(n_levels - 1, limit)
    kind = params.appearance_pyramid
    feature_level = min(params.feature_level, n_levels - 1)
    query_colours = exemplar_colours = None
    for level in progress(range(n_levels - 1, -1, -1), total=n_levels, desc="levels", quiet=quiet):
        exemplars = [levels[level] for levels in exemplar_levels]
        level_colours = None
        if context_from > 0 and level > 0:  # this level's colours: the next finer's context
            level_colours = [
                _coarse_colours(colours, ex.appearance[..., context_bands], kind)
                for ex, colours in zip(
                    exemplars, exemplar_colours or [None] * len(exemplars), strict=True
                )
            ]
        smallest = min(min(e.shape) for e in exemplars)
        k = min(params.patch_sizes[level], smallest - (1 - smallest % 2))
        solver = None  # the coarser level's solver is done: free it before building this one
        level_params = params
        if level <= feature_level and n_levels > 1 and not params.exemplar_costs_at_finest:
            level_params = replace(params, exemplar_costs=())
        query = query_levels[level]
        context = None
        scale = params.context_level_weights[level] if params.context_level_weights else 1.0
        if context_from > level and scale > 0:
            # The coarser level's colours (kept as a running collapse, so that no
            # coarser band has to stay alive) as extra guide bands, packed by the solver
            # beside the own guide bands (no concatenated copy of every guide).
            context = (
                _context(query, query_colours),
                [
                    _context(ex, colours)
                    for ex, colours in zip(exemplars, exemplar_colours, strict=True)
                ],
            )
            level_params = replace(
                level_params,
                guide_weights=params.guide_weights + tuple(scale * w for w in context_weights),
            )

        def release(e: int, level: int = level, context=context) -> None:
            # Exemplar e's bands are packed: its mapping and context are not needed any
            # more. Pyramids handed over (ReleasableLevels) drop the level now, before
            # the next exemplar is packed.
            if context is not None:
                context[1][e] = None
            if isinstance(exemplar_levels[e], ReleasableLevels):
                exemplar_levels[e].release(level)

        solver = _LevelSolver(
            query, exemplars, k, level_params, rng, timer, False, context, release
        )
        # The query's bands are packed too: the mapping goes before the features are made.
        del query, exemplars, context, release  # (release holds the context too)
        exemplar_colours = level_colours
        if isinstance(query_levels, ReleasableLevels):
            query_levels.release(level)
        # The coarser level's matches propagated from the packed lookups alone (no random
        # number drawn): before the features, so that its transients do not add to them.
        propagated = None if coarse_source is None else solver.propagate(coarse_source)
        coarse_source = solver.exemplar_valid = None  # what only propagate needed
        _trim_heap()
        solver.prepare(rng)
        _trim_heap()  # the PCA's and the feature blocks' temporaries, before the E-steps
        level_seed = int(rng.integers(0, 2**62))
        h, w = solver.query_shape
        appearance = np.zeros((h + 2 * solver.r, w + 2 * solver.r, n_appearance), dtype=np.float32)
        if propagated is None and params.init_from_guide:
            # The appearance is unknown yet: match on guide and position only.
            matches = solver.search(None, init=True, seed=level_seed, rng=rng)
        elif propagated is None:
            matches = rng.integers(0, len(solver.cand_e), size=len(solver.query_y))
        else:
            matches, propagated = propagated, None
            if params.guide_reseed > 0:
                matches = solver.reseed(matches, params.guide_reseed, level_seed, rng)
        appearance = solver.vote(matches, appearance)
        previous = np.inf
        iterations = params.max_iterations
        if level < feature_level:
            iterations = min(iterations, params.refine_iterations)
        for iteration in range(iterations):
            solver.set_appearance(appearance)
            candidates = solver.search(
                matches, init=False, seed=level_seed + 1 + iteration, rng=rng
            )
            old_cost = solver.costs(matches)
            # Exact costs of new candidates only where they differ from the old match.
            differ = np.flatnonzero(candidates != matches)
            new_cost = old_cost.copy()
            new_cost[differ] = solver.costs(candidates, differ)
            better = new_cost < old_cost
            matches = np.where(better, candidates, matches)
            value = float(np.where(better, new_cost, old_cost).mean(dtype=np.float64))
            objective[level].append(value)
            if params.vote == "mode":
                # Generalised EM: a copying M-step is kept only if it does not raise the
                # target for the new matches (the mean would be the exact minimiser).
                previous_chosen = solver.chosen
                voted = solver.vote(matches, appearance.copy())
                solver.set_appearance(voted, project=False)
                if float(solver.costs(matches).mean(dtype=np.float64)) > value:
                    solver.chosen = previous_chosen
                    solver.set_appearance(appearance, project=False)
                    log.info("level %d iteration %d: copy would raise the target", level, iteration)
                    break
                appearance = voted
            else:
                appearance = solver.vote(matches, appearance)
            log.info(
                "level %d iteration %d: target %.6g, %d matches changed",
                level,
                iteration,
                value,
                int(better.sum()),
            )
            if not better.any() or previous - value < params.tolerance * abs(previous):
                break
            previous = value
        if level == feature_level and params.final_reseed > 0:
            matches = solver.reseed(
                matches,
                params.final_reseed,
                level_seed + 1 + params.max_iterations,
                rng,
                worst=FINAL_RESEED_WORST,
                keep_detail=True,
            )
            if level > 0:  # the finer levels start from these matches and see their colours
                appearance = solver.vote(matches, appearance)
        if level == 0:  # the finest level's exact costs, while the bands are there
            solver.set_appearance(appearance, project=False)
            final_cost = solver.costs(matches)
        solver.release_search()  # what only the E-step needs, before the dense maps
        _trim_heap()
        r = solver.r  # the level's estimate copied out once the E-step's state is freed
        appearance_levels[level] = np.ascontiguousarray(appearance[r : r + h, r : r + w])
        if context_from > 0 and level > 0:
            query_colours = _coarse_colours(
                query_colours, appearance_levels[level][..., context_bands], kind
            )
        coarse_source = solver.dense_source(matches)
    assert solver is not None and matches is not None
    if params.vote == "mode":
        copy_source = coarse_source
    else:  # the mode of the final matches' sources, for front ends that copy
        # The padded estimate is not needed any more (its interior was copied into
        # appearance_levels, unless there is no padding): the mode vote may overwrite it.
        scratch = appearance if solver.r > 0 else appearance.copy()
        solver.vote(matches, scratch, kind="mode")
        appearance = scratch = None  # freed before the dense map is made
        copy_source = solver.dense_source(matches, copied=True)
    solver.chosen = None
    cost = np.full(solver.query_shape, np.nan, dtype=np.float32)
    cost[solver.query_y, solver.query_x] = final_cost
    return EngineResult(
        appearance=appearance_levels,
        source=coarse_source,
        cost=cost,
        objective=objective,
        timings=timer.seconds,
        backend=params.backend,
        copy_source=copy_source,
    )
