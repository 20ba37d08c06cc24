"""One pyramid level of the engine: packed bands, PCA features, E-step and M-step.

One module for one job: the solver class :class:`LevelSolver` and the helpers it is made of.

:class:`LevelSolver` holds everything the EM iterations of one level need; the
loop over levels and iterations is :func:`imagemap.core.engine.synthesize`.
"""

from __future__ import annotations

import contextlib
import ctypes
import logging
import sys
import threading
import time
from collections.abc import Sequence
from typing import Any

import numpy as np
from scipy import ndimage

from imagemap.core import kernels as _kernels
from imagemap.core.mapping import Mapping
from imagemap.core.params import EngineParams
from imagemap.core.search import NearestNeighborIndex, make_index

__all__ = ["FINAL_RESEED_WORST", "RESEED_WORST", "LevelSolver", "Timer", "trim_heap"]

log = logging.getLogger("imagemap")

_CHUNK = 16384  # windows per block when extracting features: bounds memory
#: A product of at most this many multiply-adds may take OpenBLAS's small-matrix kernels
#: (SkylakeX's up to 100^3), which sum in another order than the large product's: a
#: block of windows is split for the threads only where every part stays above it.
_SMALL_PRODUCT = 100**3
#: Windows per part of a block on the kernels' threads (a part's gathered windows and
#: products are each thread's scratch: 2048 windows of 7 x 7 x 4 are 1.6 MB).
_PART_ROWS = 2048
#: Up to this many dimensions the PCA's directions come from the covariance (eigh).
_COVARIANCE_DIMS = 1024
# Fixed PatchMatch work split (results do not depend on the thread count): bands of
# _BAND_ROWS rows on average, since propagation does not cross band borders, at most
# _MAX_BANDS, a multiple of _BAND_MULTIPLE of them (two threads get equal shares: 3
# bands on 2 threads took as long as 4), each with as many window centres as the others.
_MAX_BANDS = 8
_BAND_ROWS = 16
_BAND_MULTIPLE = 2
# Below this many multiply-adds, PatchMatch starts from an exact search, not at random.
_EXACT_START_FLOPS = 2e9
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


def trim_heap() -> None:
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


_MALLOC_TRIM: Any = None  # glibc's malloc_trim once looked up, False where there is none


class Timer:
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


def _centroid_frame(
    mask: np.ndarray | None, shape: tuple[int, int], origin: tuple[int, int] = (0, 0)
) -> np.ndarray:
    """(yc, xc, s, s): centroid and RMS radius of the mask (or of the whole frame), in
    the frame's coordinates (``origin``: where the mask's first pixel lies in it)."""
    if mask is None:
        mask = np.ones(shape, dtype=bool)
    ys, xs = np.nonzero(mask)
    if origin != (0, 0):  # the same integers, in the same order, as of the whole frame
        ys, xs = ys + origin[0], xs + origin[1]
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
        out[...] = np.pad(inner, ((r, r), (r, r), (0, 0)), mode=mode)  # type: ignore[call-overload]  # mode: a numpy name, checked by EngineParams
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
    return np.pad(index, r, mode=mode)  # type: ignore[call-overload]  # mode: a numpy name, checked by EngineParams


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
    source_rows, source_cols = row_index[inside_rows], col_index[inside_cols]
    if _is_run(source_rows) and _is_run(source_cols):
        # A box of the array (no reflection in the crop), and the rows and columns it goes
        # to a box of ``out`` (constant padding is at the ends): scaled straight from a
        # view, no gathered copy (the 512^2 engine's packing: 21 against 41 ms in all).
        (y0, y1), (x0, x1) = (_run_bounds(inside) for inside in (inside_rows, inside_cols))
        view = array[source_rows[0] : source_rows[-1] + 1, source_cols[0] : source_cols[-1] + 1]
        if scale is None:
            out[y0:y1, x0:x1] = view
        else:
            np.multiply(view, scale, out=out[y0:y1, x0:x1])
        out[:y0], out[y1:], out[y0:y1, :x0], out[y0:y1, x1:] = 0, 0, 0, 0
        return
    block = array[source_rows[:, None], source_cols[None, :]]
    if scale is not None:
        np.multiply(block, scale, out=block)
    if inside_rows.all() and inside_cols.all():
        out[...] = block
        return
    out[...] = 0
    out[np.ix_(inside_rows, inside_cols)] = block


def _is_run(index: np.ndarray) -> bool:
    """Whether ``index`` is a non-empty run of consecutive ascending integers."""
    return len(index) > 0 and bool(np.all(np.diff(index) == 1))


def _run_bounds(inside: np.ndarray) -> tuple[int, int]:
    """First and end of the True entries of ``inside`` (one run of them)."""
    where = np.flatnonzero(inside)
    return int(where[0]), int(where[-1]) + 1


def _box(valid: np.ndarray) -> tuple[int, int, int, int]:
    """Rows y0:y1 and columns x0:x1 of the bounding box of a non-empty boolean image."""
    rows, cols = np.flatnonzero(valid.any(axis=1)), np.flatnonzero(valid.any(axis=0))
    return int(rows[0]), int(rows[-1]) + 1, int(cols[0]), int(cols[-1]) + 1


def _channels(array: np.ndarray, channels: np.ndarray) -> np.ndarray:
    """``array[..., channels]`` without a copy when ``channels`` are all of them, in order."""
    if np.array_equal(channels, np.arange(array.shape[-1])):
        return array
    return array[..., channels]


def _randomised(dim: int, n_keep: int) -> bool:
    """Whether :func:`_fit_pca` finds the directions by a randomised range finder (it
    draws random numbers) rather than from the covariance: too large a covariance."""
    return dim > _COVARIANCE_DIMS and 4 * n_keep <= dim


def _n_keep(dim: int, fraction: float, cap: int | None) -> int:
    """Principal directions kept of ``dim``-dimensional windows: ``fraction`` of them, at
    least 1, at most ``cap``."""
    n_keep = max(1, int(round(fraction * dim)))
    return n_keep if cap is None else min(n_keep, cap)


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
    if not _randomised(dim, n_keep):
        from scipy.linalg import eigh  # deferred: start-up: only when a level is fitted

        # The kept directions alone, in float32 (LAPACK ssyevr, MRRR): the covariance
        # is a float32 product already, and float64's full eigh took twice as long (a
        # 484-dimensional guide: 23 against 12 ms); the directions agree with it to
        # |cos| > 0.99999 and hold the same variance to 1e-6.
        _, eigvecs = eigh(
            centered.T @ centered,
            subset_by_index=[dim - n_keep, dim - 1],
            driver="evr",
            overwrite_a=True,
            check_finite=False,
        )
        basis = eigvecs[:, ::-1]
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

    ``bands`` is the stack, (E, H, W, C) (exemplars, indexed by (e, y, x)) or (H, W, C)
    (the query, indexed by (y, x)), float32; a window's top-left is the index.
    ``channels`` a slice or an index array, None for all; ``scale`` one factor per
    selected channel (the exemplars' appearance is stored unscaled, once, and scaled per
    block of windows: the same float32 products as a scaled copy, without the copy).
    The windows are gathered by a numba kernel (:func:`~imagemap.core.kernels.gather_windows`)
    straight into their block, in a sliding-window view's ``(channel, ky, kx)`` order.
    """

    def __init__(
        self, bands: np.ndarray, k: int, channels=None, scale: np.ndarray | None = None
    ) -> None:
        self.bands = bands if bands.ndim == 4 else bands[None]
        self.k = k
        every = np.arange(self.bands.shape[-1])
        picked = every if channels is None else every[channels]
        self.channels = np.ascontiguousarray(picked, dtype=np.int64)
        self.scale = np.empty(0, dtype=np.float32)
        if scale is not None:
            self.scale = np.repeat(np.asarray(scale, dtype=np.float32), k * k)

    @property
    def width(self) -> int:
        """Values per window (selected channels times k^2)."""
        return len(self.channels) * self.k**2

    def __call__(
        self, index: tuple[np.ndarray, ...], out: np.ndarray | None = None, threads: bool = True
    ) -> np.ndarray:
        """The (N, width) windows at ``index``, into the first N rows of ``out`` if given
        (a buffer reused from block to block); ``threads``: the rows split over the
        kernels' threads (False inside a block that already runs on one of them)."""
        *exemplar, y, x = (np.ascontiguousarray(i, dtype=np.int32) for i in index)
        e = exemplar[0] if exemplar else np.empty(0, dtype=np.int32)
        n = y.shape[0]
        block = np.empty((n, self.width), dtype=np.float32) if out is None else out[:n]
        _kernels.gather_windows(
            self.bands, e, y, x, self.channels, self.k, self.scale, block, threads
        )
        return block


class _Scratch:
    """Scratch buffers for blocks of work that may run at once on the kernels' threads:
    ``with scratch as buffers`` lends a set no other block is using. One set per
    thread that may use them (``n_blocks`` blocks at most on the kernels' threads) is
    made by ``make`` at once, on the calling thread: made on a pooled thread, the
    buffers would come from that thread's own heap (glibc's arenas), which kept them
    resident after they were freed (512^2: +39 MB of peak)."""

    def __init__(self, make, n_blocks: int = 1) -> None:
        self.make = make
        sets = max(1, min(n_blocks, _kernels.n_threads()))
        self.free: list[Any] = [make() for _ in range(sets)]
        self.lock = threading.Lock()
        self.lent = threading.local()

    def __enter__(self):
        with self.lock:
            buffers = self.free.pop() if self.free else None
        if buffers is None:
            buffers = self.make()
        self.lent.buffers = buffers
        return buffers

    def __exit__(self, *exc) -> None:
        with self.lock:
            self.free.append(self.lent.buffers)
        self.lent.buffers = None


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

    def fit(
        self, samples: np.ndarray, fraction: float, cap: int | None, rng, largest: bool = False
    ) -> float:
        """Learn the projection from window ``samples`` (float32, overwritten: weighted
        and centred in place, no copies of the samples); with ``largest``, return the
        largest magnitude of the samples' PCA coordinates (from the centred samples
        already there: not gathered and projected again), else 0."""
        weighted = np.multiply(samples, self.sqrt_weights, out=samples)
        n_keep = _n_keep(weighted.shape[1], fraction, cap)
        mean, basis = _fit_pca(weighted, n_keep, rng, overwrite=True)
        self.matrix = np.ascontiguousarray(self.sqrt_weights[:, None] * basis)
        self.offset = mean @ basis
        if not largest:
            return 0.0
        return float(np.abs(weighted @ basis).max(initial=0.0))  # weighted: centred now

    def project(
        self,
        windows: _Windows,
        index: tuple[np.ndarray, ...],
        out: np.ndarray | None = None,
        inverse_unit: float | None = None,
        threads: bool = True,
        buffers: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> np.ndarray:
        """PCA coordinates of the windows at ``index`` (into ``out``, (N, n_components),
        which may be a column slice of a larger array), in blocks of windows at fixed
        edges (:func:`_feature_blocks`), the blocks on the kernels' threads unless
        ``threads`` is False; with ``inverse_unit``, quantized (see :func:`_store`).
        ``buffers``: (windows, product) scratch of at least N * width and N *
        n_components floats (1-D), for a single block (``threads`` False) that runs on a
        pooled thread: made by the caller, not in that thread's own heap."""
        n = index[0].shape[0]
        if out is None:
            out = np.empty((n, self.n_components), dtype=np.float32)
        matrix, offset = self.matrix, self.offset
        if matrix is None or offset is None:
            raise RuntimeError("the projection is projected before it is fitted")
        blocks = _feature_blocks(n, [self.n_components * windows.width])
        if not threads:
            blocks = [(start, min(start + _CHUNK, n)) for start in range(0, n, _CHUNK)]
        rows = max((stop - start for start, stop in blocks), default=0)
        # Buffers for the windows and their product, reused from block to block (not a
        # fresh large array per block: each would be mapped and faulted in anew).
        shapes = ((rows, windows.width), (rows, self.n_components))

        def make() -> tuple[np.ndarray, ...]:
            if buffers is not None:  # the caller's flat buffers, seen in these shapes
                pairs = zip(buffers, shapes, strict=True)
                return tuple(flat[: r * c].reshape(r, c) for flat, (r, c) in pairs)
            return tuple(np.empty(shape, dtype=np.float32) for shape in shapes)

        scratch = _Scratch(make, len(blocks) if threads else 1)

        def block(start: int, stop: int, alone: bool) -> None:
            with scratch as (gathered, product):
                sub = tuple(i[start:stop] for i in index)
                gathered = windows(sub, gathered, threads and alone)
                values = np.matmul(gathered, matrix, out=product[: stop - start])
                np.subtract(values, offset, out=values)
                _store(out[start:stop], values, inverse_unit)

        if threads:
            _kernels.run_blocks(block, blocks)
        else:
            for start, stop in blocks:
                block(start, stop, False)
        return out


def _feature_blocks(n: int, products: list[int]) -> list[tuple[int, int]]:
    """Blocks of rows 0:n for the features' products on the kernels' threads: the
    blocks of ``_CHUNK`` rows (fixed edges), each split into parts of about
    ``_PART_ROWS`` rows where every part's products (``products``: multiply-adds per
    row of each) stay above ``_SMALL_PRODUCT`` (into fewer parts where they would not;
    a block whose halves would not stays whole). The threads then hold a part's
    scratch each, not a whole block's. The blocks are the same at any thread count, so
    the bytes are too. On the Intel CPUs measured a row's product is also the same in a
    part as in the whole block (OpenBLAS's products sum each row alike at any number of
    rows above the small-matrix kernels', and a row takes those kernels only where its
    whole block does); on AMD EPYC's OpenBLAS kernels the sums follow the row count, so
    the bytes there are these parts' (equal to the whole blocks' to float32 rounding).

    Examples
    --------
    >>> _feature_blocks(20000, [196 * 39])[6:]  # 8 parts, then 2 of 1808 rows
    [(12288, 14336), (14336, 16384), (16384, 18192), (18192, 20000)]
    >>> _feature_blocks(16400, [196 * 39])[-1]  # 16 rows: not split
    (16384, 16400)
    >>> _feature_blocks(20000, [200])  # parts of 5001 rows at least: 3 in the first block
    [(0, 5461), (5461, 10922), (10922, 16384), (16384, 20000)]
    """
    blocks = []
    per_row = min(products, default=0)
    for start in range(0, n, _CHUNK):
        stop = min(start + _CHUNK, n)
        size = stop - start
        parts = -(-size // _PART_ROWS)
        while parts > 1 and (size // parts) * per_row <= _SMALL_PRODUCT:
            parts -= 1
        edges = start + (size * np.arange(parts + 1)) // parts
        blocks += [(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:], strict=True)]
    return blocks


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


class LevelSolver:
    """Everything the EM iterations of one level need, built once for the level."""

    def __init__(
        self,
        query: Mapping,
        exemplars: Sequence[Mapping],
        k: int,
        params: EngineParams,
        rng: np.random.Generator,
        timer: Timer,
        prepare: bool = True,
        context: tuple[np.ndarray, list[np.ndarray]] | None = None,
        release=None,
        exemplar_costs: tuple[float, ...] = (),
    ) -> None:
        """Pack the bands of ``query`` and ``exemplars`` (nothing of the mappings is kept),
        then, unless ``prepare`` is False, learn the PCA and make the features
        (:meth:`prepare`): with False the caller may free the mappings first.

        ``context``: (query's, exemplars') extra guide bands, (H, W, Cc) each, that
        follow the mappings' own guide bands (``params.guide_weights`` covers both):
        packed from where they are, not concatenated into a copy of every guide.
        ``release``: called with an exemplar's index once its bands are packed, so that
        the caller may free its mapping (and context) before the next one is packed;
        ``exemplars`` (a list) then loses that entry too. ``exemplar_costs``: the level
        plan's additive cost of each exemplar (:class:`~imagemap.core.params.LevelPlan`).
        """
        start = time.perf_counter()
        self.params = params
        self.r = r = k // 2
        self.window = _gaussian_window(k, params.window_sigma)
        self.timer = timer
        self.chosen: np.ndarray | None = None  # sources the mode vote copied
        # Every pixel's nearest window centre (rows, columns), for the dense source maps.
        self.nearest_centre: np.ndarray | None = None
        first = exemplars[0].appearance
        if first is None:  # the engine checks every exemplar level has appearance
            raise ValueError("an exemplar has no appearance")
        n_appearance = first.shape[2]
        guide_w = np.asarray(params.guide_weights, dtype=np.float32)
        appearance_w = np.asarray(params.appearance_weights, dtype=np.float32)
        self.guide_active = np.flatnonzero(guide_w != 0)
        self.appearance_active = np.flatnonzero(appearance_w != 0)
        n_ga, n_aa = len(self.guide_active), len(self.appearance_active)
        self.n_guide_active = n_ga
        query_context: np.ndarray | None = None
        exemplar_context: list[Any] = [None] * len(exemplars)
        if context is not None:
            query_context, exemplar_context = context
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
        heights = [e.frame[0] for e in exemplars]  # the frames' (a mapping may be a crop)
        widths = [e.frame[1] for e in exemplars]
        n_ex = len(exemplars)
        self.exemplar_shape = np.array([heights, widths], dtype=np.int64).T.copy()
        # Candidates: window centres in the (dilated) mask. Only their windows are ever
        # read, so the bands are packed for the box around them (an object often fills
        # a third of its frame): band_origin is the box's top-left in frame coordinates,
        # band_y, band_x a candidate's window's top-left in the packed bands.
        exemplar_valid = [self._frame_region(ex, r) for ex in exemplars]
        boxes = [_box(valid) for valid in exemplar_valid]
        self.band_origin = np.array([box[::2] for box in boxes], dtype=np.int32).reshape(-1, 2)
        hp = max(y1 - y0 for y0, y1, _, _ in boxes) + 2 * r
        wp = max(x1 - x0 for _, _, x0, x1 in boxes) + 2 * r
        # Guide bands scaled; appearance bands once, unscaled (the matched ones are scaled
        # where they are read: kernels and feature blocks).
        self.exemplar_guide = np.zeros((n_ex, hp, wp, n_ga), dtype=np.float32)
        self.exemplar_appearance = np.zeros((n_ex, hp, wp, n_appearance), dtype=np.float32)
        cand_e, cand_y, cand_x, positions = [], [], [], []
        # Candidate numbers over each exemplar's box of candidates (from band_origin): the
        # frame outside it has none (-1), and is not held (a third of it is the box).
        self.exemplar_lookup = np.full(
            (n_ex, max(y1 - y0 for y0, y1, _, _ in boxes), max(x1 - x0 for _, _, x0, x1 in boxes)),
            -1,
            dtype=np.int32,
        )
        n_cand = 0
        for e in range(n_ex):
            ex = exemplars[e]
            h, w = ex.frame
            y0, y1, x0, x1 = boxes[e]
            # The box's rows and columns of the padded frame (padded coordinates), in
            # the mapping's own arrays (a crop: shifted by its origin).
            oy, ox = ex.origin
            _check_crop(ex, (y0 - r, y1 + r, x0 - r, x1 + r), e)
            rows, cols = slice(y0 - oy, y1 + 2 * r - oy), slice(x0 - ox, x1 + 2 * r - ox)
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
            ys, xs = np.nonzero(exemplar_valid[e])
            self.exemplar_lookup[e, ys - y0, xs - x0] = np.arange(n_cand, n_cand + len(ys))
            n_cand += len(ys)
            cand_e.append(np.full(len(ys), e, dtype=np.int32))
            cand_y.append(ys.astype(np.int32))
            cand_x.append(xs.astype(np.int32))
            if ex.position is not None:
                positions.append(ex.position[ys - oy, xs - ox])
            else:
                frame = _centroid_frame(ex.mask, (h, w), ex.origin)
                positions.append(_positions(ys, xs, frame))
            del ex
            if release is not None:  # packed: the caller's mapping may go now
                exemplars[e] = None  # type: ignore[index]  # a list handed over with release
                release(e)
        self.cand_e = np.concatenate(cand_e)
        self.cand_y = np.concatenate(cand_y)
        self.cand_x = np.concatenate(cand_x)
        self.band_y = self.cand_y - self.band_origin[self.cand_e, 0]
        self.band_x = self.cand_x - self.band_origin[self.cand_e, 1]
        self.cand_position = np.concatenate(positions)
        costs = np.zeros(n_ex, dtype=np.float32)
        if exemplar_costs:
            if len(exemplar_costs) != n_ex:
                raise ValueError(f"{n_ex} exemplars need as many exemplar_costs")
            costs[:] = exemplar_costs
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
        # The position term's factor per query centre (Mapping.position_scale), squared as
        # the term is; 1 where the front end gives none.
        if query.position_scale is not None:
            scale = query.position_scale[self.query_y, self.query_x].astype(np.float32)
            self.query_position_scale2 = scale * scale
        else:
            self.query_position_scale2 = np.ones(len(self.query_y), dtype=np.float32)
        if query.position is not None:
            self.query_position = query.position[self.query_y, self.query_x]
        else:
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
            _Windows(self.exemplar_guide, k),
            _Windows(
                self.exemplar_appearance,
                k,
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
        fits = [
            (projection, windows)
            for projection, windows in zip(projections, self.exemplar_windows, strict=True)
            if projection.n_channels
        ]
        largest_seen = [0.0] * len(fits)

        def fit(i: int, threads: bool = True) -> None:
            projection, windows = fits[i]
            # The samples are consumed by the fit (weighted and centred in place).
            largest_seen[i] = projection.fit(
                windows(sample_index, threads=threads),
                params.pca_fraction,
                params.pca_max_components,
                rng,
                largest=params.quantize_features,
            )

        # The guide's and the appearance's fits at once, each on a thread, unless one
        # draws random numbers (a randomised range finder: the draws' order would follow
        # the threads).
        if len(fits) > 1 and not any(
            _randomised(
                windows.width,
                _n_keep(windows.width, params.pca_fraction, params.pca_max_components),
            )
            for _, windows in fits
        ):
            _kernels.run_each(lambda i: fit(i, threads=False), list(range(len(fits))))
        else:
            for i in range(len(fits)):
                fit(i)
        largest = max(largest_seen, default=0.0)
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
        self.position_dim = self.guide_projection.n_components
        self.n_init_dims = self.guide_projection.n_components + 3
        self.candidate_features = self._features(
            self.exemplar_windows, index, self.cand_position, np.sqrt(self.cand_bias)
        )
        self.query_windows = (
            _Windows(self.query_active, k, slice(0, n_ga)),
            _Windows(self.query_active, k, slice(n_ga, n_ga + n_aa)),
        )
        # The query's appearance features wait for its first estimate (set_appearance):
        # nothing reads them before (its bands are zeros until then).
        self.query_features = self._features(
            self.query_windows,
            (self.query_band_y, self.query_band_x),
            self.query_position,
            0.0,
            appearance=False,
        )
        self.band_starts = _band_starts(self.query_y, h)
        timer.add("features", start)
        self.indexes: dict[str, NearestNeighborIndex] = {}

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
        parts = []  # per exemplar, its columns: own bands, then context bands
        for e, ex in enumerate(exemplars):
            if part == "guide":
                extra = None if context is None else context[e]
                parts.append(_guide_parts(ex.guide, extra, channels, n_own))
            else:
                parts.append([(getattr(ex, part), channels)])
        std = _kernels.masked_std(parts, [ex.mask for ex in exemplars])
        floor = max(float(std.max()), 1e-12) * 1e-3
        return np.maximum(std, floor).astype(np.float32)

    @staticmethod
    def _region(mask: np.ndarray | None, shape: tuple[int, int], r: int) -> np.ndarray:
        if mask is None:
            return np.ones(shape, dtype=bool)
        return ndimage.binary_dilation(mask, iterations=max(r, 1))

    @classmethod
    def _frame_region(cls, ex: Mapping, r: int) -> np.ndarray:
        """An exemplar's window centres (its dilated mask), on its whole frame."""
        region = cls._region(ex.mask, ex.shape, r)
        if ex.frame == ex.shape:
            return region
        # A crop: dilated there (the same as on the frame while the mask stays r from a
        # side of the crop inside the frame: checked by _check_crop), put in the frame.
        whole = np.zeros(ex.frame, dtype=bool)
        oy, ox = ex.origin
        whole[oy : oy + ex.shape[0], ox : ox + ex.shape[1]] = region
        return whole

    def _features(self, windows, index, position, bias, appearance: bool = True) -> np.ndarray:
        """(N, D) features [guide PCA | weighted position | sqrt of the exemplar cost
        (candidates; 0 for the query) | appearance PCA], made in blocks of windows and
        stored as float32 or quantized (int16); without ``appearance`` its columns are 0."""
        n_guide = self.guide_projection.n_components
        n_dims = self.n_init_dims + self.appearance_projection.n_components
        dtype = np.float32 if self.inverse_unit is None else np.int16
        out = np.empty((len(position), n_dims), dtype=dtype)
        products = [
            projection.n_components * part.width
            for projection, part in zip(
                (self.guide_projection, self.appearance_projection), windows, strict=True
            )
            if projection.n_components
        ]
        blocks = _feature_blocks(len(position), products)
        rows = max((stop - start for start, stop in blocks), default=0)
        width = max(part.width for part in windows)
        n_components = max(
            self.guide_projection.n_components, self.appearance_projection.n_components
        )
        # Each block's values, and the windows and products its projections use, made
        # here on the calling thread (one set per thread), not by each projection.
        scratch = _Scratch(
            lambda: (
                np.empty((rows, n_dims), np.float32),
                np.empty(rows * width, np.float32),
                np.empty(rows * n_components, np.float32),
            ),
            len(blocks),
        )
        weight = np.float32(self.params.position_weight)

        def block(start: int, stop: int, alone: bool) -> None:
            # Blocks of windows at fixed edges (_feature_blocks), on the kernels' threads
            # (a single block projects on them itself).
            with scratch as (values, *buffers):
                sub = tuple(i[start:stop] for i in index)
                values = values[: stop - start]
                lent = None if alone else tuple(buffers)
                if n_guide:
                    self.guide_projection.project(
                        windows[0], sub, values[:, :n_guide], threads=alone, buffers=lent
                    )
                values[:, n_guide : n_guide + 2] = position[start:stop] * weight
                values[:, n_guide + 2] = bias if np.ndim(bias) == 0 else bias[start:stop]
                if self.appearance_projection.n_components and appearance:
                    self.appearance_projection.project(
                        windows[1],
                        sub,
                        values[:, self.n_init_dims :],
                        threads=alone,
                        buffers=lent,
                    )
                elif self.appearance_projection.n_components:
                    values[:, self.n_init_dims :] = 0.0
                _store(out[start:stop], values, self.inverse_unit)

        _kernels.run_blocks(block, blocks)
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

    def costs(self, matches: np.ndarray) -> np.ndarray:
        """Exact window distances of the query centres to ``matches``."""
        start = time.perf_counter()
        out = _kernels.window_costs(*self._cost_arguments(np.ascontiguousarray(matches)))
        self.timer.add("costs", start)
        return out

    def choose(self, matches: np.ndarray, candidates: np.ndarray) -> tuple[np.ndarray, int]:
        """The E-step's choice: each centre's match (int64, updated in place) replaced by
        its candidate where the candidate's exact window distance is lower; returns the
        chosen distances and how many matches changed
        (:func:`~imagemap.core.kernels.window_costs`)."""
        start = time.perf_counter()
        changed = np.empty(len(matches), dtype=np.bool_)
        out = _kernels.window_costs(
            *self._cost_arguments(matches), candidates=candidates, changed=changed
        )
        self.timer.add("costs", start)
        return out, int(np.count_nonzero(changed))

    def _cost_arguments(self, matches: np.ndarray) -> tuple:
        """The arguments of :func:`~imagemap.core.kernels.window_costs` for ``matches``."""
        return (
            self.query_active,
            self.exemplar_guide,
            self.exemplar_appearance,
            self.appearance_active,
            self.appearance_scale,
            self.window,
            self.query_band_y,
            self.query_band_x,
            self.cand_e,
            self.band_y,
            self.band_x,
            matches,
            self.query_position,
            self.cand_position,
            np.float32(self.params.position_weight**2),
            self.cand_bias,
            self.query_position_scale2,
        )

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

    def search(
        self,
        matches: np.ndarray | None,
        init: bool,
        seed: int,
        rng,
        free: bool = False,
        active: np.ndarray | None = None,
    ) -> np.ndarray:
        """E-step search: new candidate matches (PCA space) for every query centre.

        ``init``: on guide and position only (and the exemplar cost, unless ``free``: the
        cost is the last of those dimensions). ``active`` (bool per centre; PatchMatch
        from ``matches`` only): only those centres search, the others keep their match."""
        ndims = self.n_init_dims if init else self.candidate_features.shape[1]
        if init and free:
            ndims -= 1
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
                self.query_features,
                self.candidate_features,
                new,
                ndims,
                self.position_dim,
                self.query_position_scale2,
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
                self.band_origin,
                self.exemplar_shape,
                self.band_starts,
                new,
                distances,
                passes,
                self.params.stride,
                seed,
                self.position_dim,
                self.query_position_scale2,
                active,
                self.params.search_radius or 0,
            )
            self.timer.add("search", start)
            return new
        key = ("init" if init else "full") + ("-free" if init and free else "")
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
        free: bool = False,
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
        that fits the ridge a little better. With ``free`` the exemplar costs do not
        count: the relief may take its match from any exemplar.
        """
        n = self.n_init_dims - (1 if free else 0)
        matches = np.ascontiguousarray(matches, dtype=np.int64)
        scales = self.position_dim, self.query_position_scale2
        fit = _kernels.feature_distances(
            self.query_features, self.candidate_features, matches, n, *scales
        )
        # Only the worst fits may be replaced: only they search (with PatchMatch; the
        # others are still propagated from, with the matches they have).
        poor = fit > np.quantile(fit, 1.0 - worst)
        subset = poor if self.params.backend == "patchmatch" else None
        guided = self.search(matches, init=True, seed=seed, rng=rng, free=free, active=subset)
        fit_guided = _kernels.feature_distances(
            self.query_features, self.candidate_features, guided, n, *scales
        )
        take = poor & (fit_guided < ratio * fit)
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
        """Initial matches from the coarser level's dense source map (coordinates x2),
        each snapped to the nearest candidate where it is not one."""
        ys, xs = self.query_y, self.query_x
        src = coarse_source[
            np.minimum(ys // 2, coarse_source.shape[0] - 1),
            np.minimum(xs // 2, coarse_source.shape[1] - 1),
        ]
        e = src[:, 0]
        sy = np.minimum(2 * src[:, 1] + ys % 2, self.exemplar_shape[e, 0] - 1)
        sx = np.minimum(2 * src[:, 2] + xs % 2, self.exemplar_shape[e, 1] - 1)
        matches = np.empty(len(ys), dtype=np.int64)
        for ex, lookup in enumerate(self.exemplar_lookup):
            sel = np.flatnonzero(e == ex)
            # Coordinates in the lookup's box of the candidates (-1 off them).
            ly, lx = sy[sel] - self.band_origin[ex, 0], sx[sel] - self.band_origin[ex, 1]
            found = np.full(len(sel), -1, dtype=np.int64)
            inside = (ly >= 0) & (ly < lookup.shape[0]) & (lx >= 0) & (lx < lookup.shape[1])
            found[inside] = lookup[ly[inside], lx[inside]]
            off = np.flatnonzero(found < 0)  # a few (73 of 106k at 512^2's finest level)
            if len(off):
                found[off] = _nearest_candidates(lookup, ly[off], lx[off])
            matches[sel] = found
        return matches

    def dense_source(self, matches: np.ndarray, copied: bool | None = None) -> np.ndarray:
        """(H, W, 3) exemplar, y, x for every pixel: the pixel it copied (after a mode vote;
        ``copied`` overrides ``params.vote``), else its position in the match of its
        nearest window centre."""
        h, w = self.query_shape
        if self.nearest_centre is None:  # made once: the copy's map needs it again
            self.nearest_centre = ndimage.distance_transform_edt(
                self.query_lookup < 0, return_distances=False, return_indices=True
            )
        ny, nx = self.nearest_centre
        if copied is None:
            copied = self.params.vote == "mode"
        chosen_all = self.chosen if copied else None  # the mode vote's copied sources
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
            if chosen_all is not None:
                chosen = chosen_all[r + y0 : r + y1, r : r + w]
                here = chosen[..., 0] >= 0
                e = np.where(here, chosen[..., 0], e)
                # The mode vote records padded coordinates in the packed bands.
                origin = self.band_origin[e] - r
                sy = np.where(here, chosen[..., 1] + origin[..., 0], sy)
                sx = np.where(here, chosen[..., 2] + origin[..., 1], sx)
            out[y0:y1, :, 0] = e
            out[y0:y1, :, 1] = np.clip(sy, 0, self.exemplar_shape[e, 0] - 1)
            out[y0:y1, :, 2] = np.clip(sx, 0, self.exemplar_shape[e, 1] - 1)
        return out


def _nearest_candidates(lookup: np.ndarray, ys: np.ndarray, xs: np.ndarray) -> np.ndarray:
    """The candidate (``lookup``'s number, -1 off the candidates) nearest to each point
    (ys, xs) of the lookup's coordinates (which may lie outside it): the Euclidean feature
    transform of a box holding every candidate and every point, the same nearest
    candidates (ties too) as of the exemplar's whole frame (scipy's transform is
    separable and exact: a box holding every feature and point changes none; 2957 random
    masks and points compared), at a fraction of the frame's cost."""
    y0, x0 = min(0, int(ys.min())), min(0, int(xs.min()))
    y1 = max(lookup.shape[0], int(ys.max()) + 1)
    x1 = max(lookup.shape[1], int(xs.max()) + 1)
    not_candidate = np.ones((y1 - y0, x1 - x0), dtype=bool)
    not_candidate[-y0 : -y0 + lookup.shape[0], -x0 : -x0 + lookup.shape[1]] = lookup < 0
    ny, nx = ndimage.distance_transform_edt(
        not_candidate, return_distances=False, return_indices=True
    )
    at = (ys - y0, xs - x0)
    return lookup[ny[at] + y0, nx[at] + x0]


def _band_starts(ys: np.ndarray, height: int) -> np.ndarray:
    """The first centre of each PatchMatch band and the end (``band_starts``), from the
    centres' rows ``ys`` (sorted): whole rows per band, about as many centres in each.

    The bands span the rows the object's window centres span (not the frame's: an
    object in a tight frame, as the pose stage crops it, still gets its threads).

    Examples
    --------
    >>> _band_starts(np.repeat(np.arange(64), 10), 64).tolist()
    [0, 160, 320, 480, 640]
    >>> _band_starts(np.repeat(np.arange(40), 10), 40).tolist()  # 2.5 bands: 2
    [0, 200, 400]
    """
    top, bottom = (int(ys.min()), int(ys.max()) + 1) if len(ys) else (0, height)
    n_bands = int(np.clip((bottom - top) // _BAND_ROWS, 1, _MAX_BANDS))
    if n_bands > _BAND_MULTIPLE:
        n_bands -= n_bands % _BAND_MULTIPLE
    # The row where each band's share of the centres begins (a band's last row may hold
    # a little more or less than its share: bands hold whole rows).
    shares = np.linspace(0, len(ys), n_bands + 1)[1:-1].astype(np.int64)
    row_edges = np.unique(np.concatenate([[top], ys[shares] if len(ys) else [], [bottom]]))
    return np.searchsorted(ys, row_edges.astype(np.int64), side="left").astype(np.int64)


def _check_crop(ex: Mapping, reach: tuple[int, int, int, int], e: int) -> None:
    """ValueError unless the rows y0:y1 and columns x0:x1 (frame coordinates) that the
    exemplar's windows read (``reach``) lie inside its crop, or past it only where the
    crop's side is the frame's (padded as the frame would be)."""
    if ex.frame == ex.shape:
        return
    y0, y1, x0, x1 = reach
    (oy, ox), (h, w), (fh, fw) = ex.origin, ex.shape, ex.frame
    if (
        (y0 < oy and oy > 0)
        or (y1 > oy + h and oy + h < fh)
        or (x0 < ox and ox > 0)
        or (x1 > ox + w and ox + w < fw)
    ):
        raise ValueError(
            f"exemplar {e}: its windows read rows {y0}:{y1}, columns {x0}:{x1} of the "
            f"frame, past its crop at {ex.origin} of {ex.shape}: crop with a larger margin"
        )


def _guide_parts(guide, context, active, n_own=None):
    """The ``active`` guide channels as (array, channel indices) parts: of the mapping's
    own ``guide`` bands (the first ``n_own``, default all of them), then of the
    ``context`` bands (None: none)."""
    n_own = guide.shape[2] if n_own is None else n_own
    parts = [(guide, active[active < n_own])]
    if context is not None:
        parts.append((context, active[active >= n_own] - n_own))
    return [(array, channels) for array, channels in parts if len(channels)]
