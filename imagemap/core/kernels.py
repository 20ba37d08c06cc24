"""Numba kernels for the loops that cannot be vectorized.

One module for one job: a collection of numba kernels and the thread pool that runs them.

All kernels are deterministic for any number of threads: random numbers come
from a counter-based hash of (seed, pixel, pass, trial), never from a shared
generator, and parallel work is split into fixed bands of rows whose members
only read matches inside their own band.

Threads: every kernel is a *serial* numba function (``nogil=True``) over a range
of its work items, and the public wrappers below run those ranges on a small
pool of Python threads. numba's ``parallel=True`` would do the same, but its
parfors compilation costs about three times as much on a fresh numba cache
(measured: 82 s against 31 s for the six kernels on a busy 2-core machine) and
loads a threading layer. The work items are independent (pixels, rows of one
colour of a red-black sweep, PatchMatch bands), so the split never changes a
result. The thread count is numba's (``NUMBA_NUM_THREADS``, or
``numba.set_num_threads`` once numba's own pool is up).

Coordinates: a *candidate* is an exemplar window centre, numbered 0..N-1, with
``cand_e, cand_y, cand_x`` its exemplar index and centre (unpadded coordinates);
``exemplar_lookup[e, y - lookup_origin[e, 0], x - lookup_origin[e, 1]]`` maps a
centre back to its number (-1 when it is not a candidate): the lookup covers the box
of each exemplar's candidates, not its frame. A *query centre* m has ``query_y[m], query_x[m]`` and
``query_lookup[y, x] == m``. Band arrays are padded by the window radius r, so
the window of centre (y, x) is ``bands[y:y + k, x:x + k]``.
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import numpy as np
from llvmlite import ir
from numba import config, njit, types
from numba.core import cgutils
from numba.extending import intrinsic

_POOLS: dict[tuple[int, int], ThreadPoolExecutor] = {}
#: Pieces of work per thread (the pool balances uneven pieces).
_PIECES_PER_THREAD = 4
#: The kernels' index type where an index is never negative: numba checks every signed
#: index for a negative value to wrap around the axis, not an unsigned one (mixed with a
#: signed integer, an unsigned one gives a float in numba: both sides made unsigned).
_U = np.uint64


def n_threads() -> int:
    """Threads the kernels use: numba's setting (``numba.set_num_threads`` honoured)."""
    try:
        from numba.np.ufunc import (
            parallel,
        )  # deferred: start-up: numba only when its threads are asked for

        if parallel._is_initialized:  # numba's pool is up: its (thread-local) setting
            import numba  # deferred: start-up: numba only when its threads are asked for

            return max(1, int(numba.get_num_threads()))
    except (ImportError, AttributeError):  # pragma: no cover - other numba versions
        pass
    return max(1, int(getattr(config, "NUMBA_NUM_THREADS", 1)))


def _pool(threads: int) -> ThreadPoolExecutor:
    # Keyed by process too: a forked child inherits the dict but not the threads.
    key = (os.getpid(), threads)
    pool = _POOLS.get(key)
    if pool is None:
        pool = _POOLS[key] = ThreadPoolExecutor(threads, thread_name_prefix="imagemap")
    return pool


def _run(function, n_items: int, min_piece: int = 1) -> None:
    """``function(start, stop)`` over [0, n_items) in pieces, on the thread pool."""
    threads = n_threads()
    pieces = min(threads * _PIECES_PER_THREAD, max(1, n_items // max(min_piece, 1)))
    if threads == 1 or pieces <= 1:
        function(0, n_items)
        return
    edges = np.linspace(0, n_items, pieces + 1).astype(np.int64)
    pool = _pool(threads)
    futures = [
        pool.submit(function, int(a), int(b))
        for a, b in zip(edges[:-1], edges[1:], strict=True)
        if b > a
    ]
    for future in futures:
        future.result()


def _run_each(function, items: list) -> None:
    """``function(item)`` for every item, on the thread pool."""
    threads = n_threads()
    if threads == 1 or len(items) <= 1:
        for item in items:
            function(item)
        return
    pool = _pool(threads)
    for future in [pool.submit(function, item) for item in items]:
        future.result()


def run_each(function, items: list) -> None:
    """``function(item)`` for every item, on the thread pool (in order with one thread)."""
    _run_each(function, items)


def run_blocks(function, blocks: list[tuple[int, int]]) -> None:
    """``function(start, stop, alone)`` for every block of items ``(start, stop)`` (fixed
    by the caller: the same blocks at any thread count), the blocks on the thread pool.
    ``alone`` is True when there is a single block, run on the calling thread:
    ``function`` may then use the pool itself (never from a pooled block: a block
    waiting for work queued behind it would wait forever)."""
    if len(blocks) <= 1:
        for start, stop in blocks:
            function(start, stop, True)
        return
    _run_each(lambda block: function(block[0], block[1], False), blocks)


@njit(cache=True, nogil=True)
def _gather_windows(bands, e, y, x, channels, k, scale, out, start, stop):
    """Rows [start, stop) of :func:`gather_windows`.

    Indexed by unsigned integers (:data:`_U`): numba wraps a signed index that is negative
    around the axis (a compare and an add per index, which kept LLVM from streamlining
    the copy); the indices here are never negative. Twice as fast (0.6-0.9 against
    1.3-1.6 ns a value, 7 x 7 and 11 x 11 windows of 3 and 4 channels), the same values.
    """
    n_channels = channels.shape[0]
    scaled = scale.shape[0] > 0
    area = k * k
    for i in range(start, stop):
        row = _U(i)
        ee = _U(e[i]) if e.shape[0] > 0 else _U(0)
        yy = _U(y[i])
        xx = _U(x[i])
        # Written in the row's order (twice as fast as read in the bands' order).
        for ci in range(n_channels):
            c = _U(channels[ci])
            for oy in range(k):
                j = _U(ci * area + oy * k)
                band_row = yy + _U(oy)
                for ox in range(k):
                    column = _U(ox)
                    value = bands[ee, band_row, xx + column, c]
                    if scaled:
                        value = value * scale[j + column]
                    out[row, j + column] = value


def gather_windows(bands, e, y, x, channels, k, scale, out, threads=True) -> None:
    """The k x k windows of some channels of a band stack, flattened, into ``out``.

    Row i of ``out`` (N, len(channels) k^2) float32 becomes the window whose top-left is
    ``bands[e[i], y[i], x[i]]`` (``bands`` (E, H, W, C) float32; ``e`` empty: exemplar 0),
    in ``(channel, ky, kx)`` order (a sliding-window view's), each value times
    ``scale[j]`` (float32, one per column; empty: none): the same float32 products as
    ``view[e, y, x][:, channels].reshape(N, -1) * scale``. ``threads``: rows split over
    the thread pool (False from a pooled block, see :func:`run_blocks`).
    """
    n = y.shape[0]
    args = (bands, e, y, x, channels, k, scale, out)
    if not threads:
        _gather_windows(*args, 0, n)
        return
    _run(lambda a, b: _gather_windows(*args, a, b), n, 1024)


_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_MIX1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX2 = np.uint64(0x94D049BB133111EB)


@njit(cache=True, nogil=True)
def _splitmix(z):
    z = (z ^ (z >> np.uint64(30))) * _MIX1
    z = (z ^ (z >> np.uint64(27))) * _MIX2
    return z ^ (z >> np.uint64(31))


@njit(cache=True, nogil=True)
def _random_below(seed, a, b, c, n):
    """A deterministic pseudo-random integer in [0, n) for the counter (seed, a, b, c)."""
    z = _splitmix(np.uint64(seed) + _GOLDEN)
    z = _splitmix(z ^ (np.uint64(a) * _GOLDEN))
    z = _splitmix(z ^ (np.uint64(b) * _MIX1))
    z = _splitmix(z ^ (np.uint64(c) * _MIX2))
    return np.int64(z % np.uint64(n))


@njit(cache=True, nogil=True)
def _sq_dist(a, b, ndims):
    s = np.float32(0.0)
    for i in range(ndims):
        d = np.float32(a[i]) - np.float32(b[i])  # float32 or quantized (int16) features
        s += d * d
    return s


@njit(cache=True, nogil=True)
def _sq_dist_scaled(a, b, ndims, position_dim, position_scale):
    """:func:`_sq_dist` with the two position columns from ``position_dim`` times
    ``position_scale`` (a query pixel's own factor on the position term): the plain sum
    (one loop, as fast as before) corrected by the position columns' share."""
    s = _sq_dist(a, b, ndims)
    if position_scale == 1.0 or position_dim < 0 or position_dim + 2 > ndims:
        return s
    d0 = np.float32(a[position_dim]) - np.float32(b[position_dim])
    d1 = np.float32(a[position_dim + 1]) - np.float32(b[position_dim + 1])
    return s + (position_scale - np.float32(1.0)) * (d0 * d0 + d1 * d1)


#: Feature columns summed between two checks of :func:`_sq_dist_below` against its bound.
#: A check costs a compare; most PatchMatch trials lose, many within the first blocks
#: (the guide's leading PCA components come first).
_BOUND_CHECK_COLUMNS = 8


@njit(cache=True, nogil=True)
def _sq_dist_below(a, b, ndims, position_dim, position_scale, bound):
    """:func:`_sq_dist_scaled` where it is below ``bound``; elsewhere some value at least
    ``bound`` (the sum stops as soon as it cannot end below it).

    The same float32 operations in the same order as :func:`_sq_dist_scaled`, so a
    result below ``bound`` has the same bits, and a trial is never won or lost
    differently: every term is a square (not negative), so each partial sum is at most
    the full one (rounding is monotonic), and the position columns' correction (negative
    where ``position_scale`` < 1) is computed first and added to the partial sum before
    each comparison."""
    scaled = not (position_scale == 1.0 or position_dim < 0 or position_dim + 2 > ndims)
    correction = np.float32(0.0)
    if scaled:
        d0 = np.float32(a[position_dim]) - np.float32(b[position_dim])
        d1 = np.float32(a[position_dim + 1]) - np.float32(b[position_dim + 1])
        correction = (position_scale - np.float32(1.0)) * (d0 * d0 + d1 * d1)
    s = np.float32(0.0)
    i = 0
    while i < ndims:
        stop = min(i + _BOUND_CHECK_COLUMNS, ndims)
        for j in range(i, stop):
            d = np.float32(a[j]) - np.float32(b[j])
            s += d * d
        if stop < ndims and s + correction >= bound:
            return s + correction
        i = stop
    if not scaled:
        return s
    return s + correction


@njit(cache=True, nogil=True)
def _feature_distances(
    query_features, candidate_features, matches, ndims, out, start, stop, position_dim, scales
):
    for m in range(start, stop):
        out[m] = _sq_dist_scaled(
            query_features[m], candidate_features[matches[m]], ndims, position_dim, scales[m]
        )


def feature_distances(
    query_features, candidate_features, matches, ndims, position_dim=-2, position_scales=None
):
    """Squared distance over the first ``ndims`` feature columns for each (m, matches[m]);
    the position columns (``position_dim`` and the next) times ``position_scales[m]``."""
    out = np.empty(matches.shape[0], dtype=np.float32)
    if position_scales is None:
        position_scales = np.ones(matches.shape[0], dtype=np.float32)
    _run(
        lambda a, b: _feature_distances(
            query_features,
            candidate_features,
            matches,
            ndims,
            out,
            a,
            b,
            position_dim,
            position_scales,
        ),
        matches.shape[0],
        4096,
    )
    return out


#: Random-search trials a PatchMatch visit may draw (one per halving of a radius < 2^63).
_MAX_TRIALS = 64


@njit(cache=True, nogil=True)
def _patchmatch_band(
    band,
    query_features,
    candidate_features,
    ndims,
    query_y,
    query_x,
    query_lookup,
    cand_e,
    cand_y,
    cand_x,
    exemplar_lookup,
    lookup_origin,
    exemplar_shape,
    band_starts,
    matches,
    distances,
    n_passes,
    stride,
    seed,
    position_dim,
    position_scales,
    active,
    max_radius,
):
    """PatchMatch of one band of query centres (see :func:`patchmatch`)."""
    n_candidates = candidate_features.shape[0]
    height = query_lookup.shape[0]
    width = query_lookup.shape[1]
    m0 = band_starts[band]
    m1 = band_starts[band + 1]
    if m1 <= m0:
        return
    row0 = query_y[m0]
    row1 = query_y[m1 - 1]
    # One random-search trial per halving of the radius (at most 63 for any int64 radius).
    offsets = np.empty((_MAX_TRIALS, 2), dtype=np.int64)
    for p in range(n_passes):
        forward = p % 2 == 0
        step = stride if forward else -stride
        for t in range(m1 - m0):
            m = m0 + t if forward else m1 - 1 - t
            if active.shape[0] > 0 and not active[m]:
                continue
            following = m + 1 if forward else m - 1
            if m0 <= following < m1:
                _prefetch_next(
                    candidate_features,
                    following,
                    p,
                    step,
                    seed,
                    row0,
                    row1,
                    query_y,
                    query_x,
                    query_lookup,
                    cand_e,
                    cand_y,
                    cand_x,
                    exemplar_lookup,
                    lookup_origin,
                    exemplar_shape,
                    matches,
                )
            y = query_y[m]
            x = query_x[m]
            best = matches[m]
            best_d = distances[m]
            qf = query_features[m]
            scale = position_scales[m]
            # Propagation: the neighbour already visited in this pass, shifted.
            for axis in range(2):
                ny = y - step if axis == 0 else y
                nx = x - step if axis == 1 else x
                if ny < row0 or ny > row1 or nx < 0 or nx >= width or ny >= height:
                    continue
                n = query_lookup[ny, nx]
                if n < 0:
                    continue
                c = matches[n]
                e = cand_e[c]
                cy = cand_y[c] + (step if axis == 0 else 0)
                cx = cand_x[c] + (step if axis == 1 else 0)
                if cy < 0 or cx < 0 or cy >= exemplar_shape[e, 0] or cx >= exemplar_shape[e, 1]:
                    continue
                cc = _looked_up(exemplar_lookup, lookup_origin, e, cy, cx)
                if cc < 0 or cc == best:
                    continue
                d = _sq_dist_below(qf, candidate_features[cc], ndims, position_dim, scale, best_d)
                if d < best_d:
                    best = cc
                    best_d = d
            # Random search around the current best, radius halving.
            e = cand_e[best]
            radius = max(exemplar_shape[e, 0], exemplar_shape[e, 1])
            if max_radius > 0:
                radius = min(radius, max_radius)
            # The trials' offsets depend on the counter alone: drawn first, and the rows
            # they reach from the current best prefetched (most trials lose, so best
            # mostly stays), then tried in the same order as drawn.
            n_trials = 0
            while radius >= 1:
                offsets[n_trials, 0] = (
                    _random_below(seed, m, p, 2 * n_trials, 2 * radius + 1) - radius
                )
                offsets[n_trials, 1] = (
                    _random_below(seed, m, p, 2 * n_trials + 1, 2 * radius + 1) - radius
                )
                cy = min(max(cand_y[best] + offsets[n_trials, 0], 0), exemplar_shape[e, 0] - 1)
                cx = min(max(cand_x[best] + offsets[n_trials, 1], 0), exemplar_shape[e, 1] - 1)
                cc = _looked_up(exemplar_lookup, lookup_origin, e, cy, cx)
                if cc >= 0:
                    _prefetch_row(candidate_features, cc)
                radius //= 2
                n_trials += 1
            for trial in range(n_trials):
                cy = min(max(cand_y[best] + offsets[trial, 0], 0), exemplar_shape[e, 0] - 1)
                cx = min(max(cand_x[best] + offsets[trial, 1], 0), exemplar_shape[e, 1] - 1)
                cc = _looked_up(exemplar_lookup, lookup_origin, e, cy, cx)
                if cc >= 0 and cc != best:
                    d = _sq_dist_below(
                        qf, candidate_features[cc], ndims, position_dim, scale, best_d
                    )
                    if d < best_d:
                        best = cc
                        best_d = d
            # One jump anywhere: lets a pixel leave a poor exemplar.
            cc = _random_below(seed, m, p, 1000003, n_candidates)
            d = _sq_dist_below(qf, candidate_features[cc], ndims, position_dim, scale, best_d)
            if d < best_d:
                best = cc
                best_d = d
            matches[m] = best
            distances[m] = best_d


def _prefetch_row_intrinsic(typingctx, array, row):
    """Ask the CPU to fetch the start of row ``row`` of a 2-D C-contiguous ``array``
    into its caches (LLVM's ``prefetch``: read, high locality); changes no value."""
    signature = types.void(array, row)

    def codegen(context, builder, sig, args):
        array_type, row_type = sig.args
        view = context.make_array(array_type)(context, builder, args[0])
        index = context.cast(builder, args[1], row_type, types.intp)
        pointer = cgutils.get_item_pointer2(
            context,
            builder,
            data=view.data,
            shape=cgutils.unpack_tuple(builder, view.shape),
            strides=cgutils.unpack_tuple(builder, view.strides),
            layout=array_type.layout,
            inds=[index, context.get_constant(types.intp, 0)],
        )
        byte_pointer = ir.IntType(8).as_pointer()
        i32 = ir.IntType(32)
        prefetch = builder.module.declare_intrinsic(
            "llvm.prefetch",
            [byte_pointer],
            ir.FunctionType(ir.VoidType(), [byte_pointer, i32, i32, i32]),
        )
        # (address, 0: read, 3: keep in every cache level, 1: data)
        builder.call(
            prefetch,
            [
                builder.bitcast(pointer, byte_pointer),
                ir.Constant(i32, 0),
                ir.Constant(i32, 3),
                ir.Constant(i32, 1),
            ],
        )
        return context.get_dummy_value()

    return signature, codegen


#: ``_prefetch_row(array, row)`` inside numba code (numba passes the typing context itself;
#: typed Any for mypy, which would count three arguments).
_prefetch_row: Any = intrinsic(_prefetch_row_intrinsic)


@njit(cache=True, nogil=True, inline="always")  # a call: no faster than no prefetch
def _prefetch_next(
    candidate_features,
    m,
    p,
    step,
    seed,
    row0,
    row1,
    query_y,
    query_x,
    query_lookup,
    cand_e,
    cand_y,
    cand_x,
    exemplar_lookup,
    lookup_origin,
    exemplar_shape,
    matches,
):
    """Prefetch the feature rows that query centre ``m`` of pass ``p`` will read first and
    that are known already: its jump's (a random row anywhere, most often a miss of
    every cache) and its propagation from the row before (that row's matches are final).
    Issued one centre ahead, while the current centre's distances are summed: the
    same trials and decisions (with the random search's own prefetches, the largest
    searches of the 200x150 and 512^2 tasks took 0.62-0.80 of their time)."""
    _prefetch_row(
        candidate_features, _random_below(seed, m, p, 1000003, candidate_features.shape[0])
    )
    y = query_y[m] - step
    if y < row0 or y > row1 or y >= query_lookup.shape[0]:
        return
    n = query_lookup[y, query_x[m]]
    if n < 0:
        return
    c = matches[n]
    e = cand_e[c]
    cy = cand_y[c] + step
    if cy < 0 or cy >= exemplar_shape[e, 0]:
        return
    cc = _looked_up(exemplar_lookup, lookup_origin, e, cy, cand_x[c])
    if cc >= 0:
        _prefetch_row(candidate_features, cc)


@njit(cache=True, nogil=True)
def _looked_up(exemplar_lookup, lookup_origin, e, y, x):
    """The candidate at frame pixel (y, x) of exemplar e: the lookup covers the box of
    its candidates from ``lookup_origin[e]`` (-1 outside it, as anywhere not a centre)."""
    ly = y - lookup_origin[e, 0]
    lx = x - lookup_origin[e, 1]
    if ly < 0 or lx < 0 or ly >= exemplar_lookup.shape[1] or lx >= exemplar_lookup.shape[2]:
        return -1
    return exemplar_lookup[e, ly, lx]


def patchmatch(
    query_features,
    candidate_features,
    ndims,
    query_y,
    query_x,
    query_lookup,
    cand_e,
    cand_y,
    cand_x,
    exemplar_lookup,
    lookup_origin,
    exemplar_shape,
    band_starts,
    matches,
    distances,
    n_passes,
    stride,
    seed,
    position_dim=-2,
    position_scales=None,
    active=None,
    max_radius=0,
):
    """PatchMatch over the candidates of several exemplars, in place on matches/distances.

    Each pass visits the query centres of a band in scan order (reversed on odd
    passes): propagation from the previous neighbour in x and y (shifted by one
    stride), random search around the current match with halving radius, and one
    uniformly random candidate (a jump to any exemplar). Bands are independent
    (propagation does not cross their borders): one thread each. ``position_scales``
    (one per query centre; default 1) multiply the position columns (``position_dim``
    and the next) of the distances. ``active`` (M,) bool: only those centres search (the
    others keep their matches and are still propagated from); None: all. ``max_radius``
    (pixels; 0: none): the random search starts at this radius, not at the exemplar's
    larger side.
    """
    if position_scales is None:
        position_scales = np.ones(matches.shape[0], dtype=np.float32)
    active = np.empty(0, dtype=np.bool_) if active is None else np.asarray(active, dtype=np.bool_)

    def band(b):
        _patchmatch_band(
            b,
            query_features,
            candidate_features,
            ndims,
            query_y,
            query_x,
            query_lookup,
            cand_e,
            cand_y,
            cand_x,
            exemplar_lookup,
            lookup_origin,
            exemplar_shape,
            band_starts,
            matches,
            distances,
            n_passes,
            stride,
            seed,
            position_dim,
            position_scales,
            active,
            max_radius,
        )

    _run_each(band, list(range(band_starts.shape[0] - 1)))


#: The exact costs' sums may be reassociated (vectorized): they are float64 sums of float32
#: terms, so the order moves a sum by about 1e-16 of itself, far below the float32 cost's
#: rounding (the 200x150 and 512^2 engine calls' costs came out bit for bit the same,
#: 13-16 % faster).
_COSTS_FASTMATH = {"reassoc"}


@njit(cache=True, nogil=True, fastmath=_COSTS_FASTMATH)
def _window_costs(
    start,
    stop,
    out,
    changed,
    matches,
    candidates,
    query_bands,
    exemplar_guide,
    exemplar_appearance,
    appearance_channels,
    appearance_scale,
    window_weights,
    query_y,
    query_x,
    cand_e,
    cand_y,
    cand_x,
    query_position,
    cand_position,
    position_weight2,
    cand_bias,
    position_scales,
):
    """Window distances of query centres [start, stop) (see :func:`window_costs`); with
    ``candidates`` (not empty), the E-step's choice."""
    k = window_weights.shape[0]
    n_guide = exemplar_guide.shape[3]
    n_appearance = appearance_channels.shape[0]
    trials = 1 if candidates.shape[0] == 0 else 2
    for m in range(start, stop):
        qy = _U(query_y[m])  # unsigned: no wrap-around check per index (see _U)
        qx = _U(query_x[m])
        for trial in range(trials):  # the match, then the candidate
            c = matches[m] if trial == 0 else candidates[m]
            if trial == 1:
                changed[m] = False
                if c == matches[m]:  # the candidate's distance only where it differs
                    break
            e = _U(cand_e[c])
            ey = _U(cand_y[c])
            ex = _U(cand_x[c])
            s = 0.0
            for oy in range(k):
                for ox in range(k):
                    w = window_weights[oy, ox]
                    uy, ux = _U(oy), _U(ox)
                    query_pixel = query_bands[qy + uy, qx + ux]
                    acc = 0.0
                    for ch in range(n_guide):
                        d = query_pixel[ch] - exemplar_guide[e, ey + uy, ex + ux, _U(ch)]
                        acc += d * d
                    for j in range(n_appearance):
                        a = exemplar_appearance[e, ey + uy, ex + ux, _U(appearance_channels[j])]
                        d = query_pixel[n_guide + j] - a * appearance_scale[j]
                        acc += d * d
                    s += w * acc
            dy = query_position[m, 0] - cand_position[c, 0]
            dx = query_position[m, 1] - cand_position[c, 1]
            s += position_weight2 * position_scales[m] * (dy * dy + dx * dx) + cand_bias[c]
            cost = np.float32(s)
            if trial == 0:
                out[m] = cost
            elif cost < out[m]:
                out[m] = cost
                matches[m] = c
                changed[m] = True


def window_costs(
    query_bands,
    exemplar_guide,
    exemplar_appearance,
    appearance_channels,
    appearance_scale,
    window_weights,
    query_y,
    query_x,
    cand_e,
    cand_y,
    cand_x,
    matches,
    query_position,
    cand_position,
    position_weight2,
    cand_bias,
    position_scales=None,
    *,
    candidates=None,
    changed=None,
):
    """Exact weighted window distance for each query centre and its match.

    ``query_bands`` (Hq + 2r, Wq + 2r, Cg + Ca) holds the matched bands already
    multiplied by their weights: Cg guide bands, then Ca appearance bands;
    ``exemplar_guide`` (E, Hmax + 2r, Wmax + 2r, Cg) the exemplars' guide bands,
    weighted; ``exemplar_appearance`` (E, Hmax + 2r, Wmax + 2r, A) their appearance
    bands unweighted, of which ``appearance_channels`` (Ca,) are matched with the
    weights ``appearance_scale`` (Ca,), applied here (one copy of the bands);
    ``window_weights`` (k, k) is the Gaussian window, summing to one;
    ``cand_bias`` (N,) an additive cost per candidate (exemplar preference);
    ``position_scales`` (M,) a factor per query centre on the position term (default 1).

    With ``candidates`` (M,) int64 and ``changed`` (M,) bool, the E-step's choice: each
    centre's match (``matches``, int64, updated in place) is replaced by its candidate
    where the candidate's distance is lower (``changed`` True there), and the distances
    returned are the chosen ones. A centre's query window is read for both distances in
    one pass, the candidate's made only where it differs from the match: the same values
    and choices as both distances made apart and compared.
    """
    n = matches.shape[0]
    out = np.empty(n, dtype=np.float32)
    if position_scales is None:
        position_scales = np.ones(n, dtype=np.float32)
    if candidates is None:
        candidates, changed = np.empty(0, dtype=np.int64), np.empty(0, dtype=np.bool_)
    _run(
        lambda a, b: _window_costs(
            a,
            b,
            out,
            changed,
            matches,
            candidates,
            query_bands,
            exemplar_guide,
            exemplar_appearance,
            appearance_channels,
            appearance_scale,
            window_weights,
            query_y,
            query_x,
            cand_e,
            cand_y,
            cand_x,
            query_position,
            cand_position,
            position_weight2,
            cand_bias,
            position_scales,
        ),
        n,
        1024,
    )
    return out


@njit(cache=True, nogil=True)
def _source_rows(row0, row1, query_lookup, cand_e, cand_y, cand_x, matches, sources):
    """Rows [row0, row1) of :func:`_match_sources`."""
    width = query_lookup.shape[1]
    for y in range(row0, row1):
        for x in range(width):
            m = query_lookup[y, x]
            if m < 0:
                sources[y, x, 0] = -1
                continue
            c = matches[m]
            sources[y, x, 0] = cand_e[c]
            sources[y, x, 1] = cand_y[c]
            sources[y, x, 2] = cand_x[c]


def _match_sources(query_lookup, cand_e, cand_y, cand_x, matches) -> np.ndarray:
    """(Hq, Wq, 3) int32: at each window centre its match's exemplar, y and x (e = -1
    where no window is centred). The votes read a centre's match from here in one step
    instead of through the lookup, the matches and the candidates' three arrays (the
    same values: the same bytes, 17-25 % faster)."""
    sources = np.empty(query_lookup.shape + (3,), dtype=np.int32)
    _run(
        lambda a, b: _source_rows(a, b, query_lookup, cand_e, cand_y, cand_x, matches, sources),
        query_lookup.shape[0],
        8,
    )
    return sources


@njit(cache=True, nogil=True)
def _vote_rows(row0, row1, exemplar_appearance, window_weights, sources, out):
    """Rows [row0, row1) of :func:`vote`. The first three channels' sums are scalars (in
    registers: an array's element is stored and loaded again at every addition, which
    made each pixel's 49 additions a chain of store-to-load waits), the rest an array:
    the same additions in the same order, 0.6-0.75 of the time at three channels."""
    k = window_weights.shape[0]
    height = sources.shape[0]
    width = sources.shape[1]
    channels = exemplar_appearance.shape[3]
    more = np.zeros(max(channels - 3, 0), dtype=np.float64)  # channels past the third
    for py in range(row0, row1):
        for px in range(out.shape[1]):
            wsum = 0.0
            sum0 = 0.0
            sum1 = 0.0
            sum2 = 0.0
            more[:] = 0.0
            for oy in range(k):
                cy = py - oy  # window centre in unpadded query coordinates
                if cy < 0 or cy >= height:
                    continue
                for ox in range(k):
                    cx = px - ox
                    if cx < 0 or cx >= width:
                        continue
                    source = sources[cy, cx]
                    if source[0] < 0:
                        continue
                    w = window_weights[oy, ox]
                    # Unsigned: no wrap-around check per index (see _U).
                    pixel = exemplar_appearance[
                        _U(source[0]), _U(source[1]) + _U(oy), _U(source[2]) + _U(ox)
                    ]
                    sum0 += w * pixel[0]
                    if channels > 1:
                        sum1 += w * pixel[1]
                    if channels > 2:
                        sum2 += w * pixel[2]
                    for ch in range(3, channels):
                        more[ch - 3] += w * pixel[ch]
                    wsum += w
            if wsum > 0:
                out[py, px, 0] = sum0 / wsum
                if channels > 1:
                    out[py, px, 1] = sum1 / wsum
                if channels > 2:
                    out[py, px, 2] = sum2 / wsum
                for ch in range(3, channels):
                    out[py, px, ch] = more[ch - 3] / wsum


def vote(
    exemplar_appearance,
    window_weights,
    query_lookup,
    cand_e,
    cand_y,
    cand_x,
    matches,
    out,
):
    """M-step: every padded query pixel becomes the weighted mean of its window estimates.

    ``out`` (Hq + 2r, Wq + 2r, Ca) receives the mean where at least one window
    covers a pixel and keeps its value elsewhere.
    """
    sources = _match_sources(query_lookup, cand_e, cand_y, cand_x, matches)
    _run(
        lambda a, b: _vote_rows(a, b, exemplar_appearance, window_weights, sources, out),
        out.shape[0],
        8,
    )


@njit(cache=True, nogil=True)
def _vote_mode_rows(row0, row1, exemplar_appearance, window_weights, sources, out, chosen):
    k = window_weights.shape[0]
    height = sources.shape[0]
    width = sources.shape[1]
    channels = exemplar_appearance.shape[3]
    for py in range(row0, row1):
        ke = np.empty(k * k, dtype=np.int64)
        ky = np.empty(k * k, dtype=np.int64)
        kx = np.empty(k * k, dtype=np.int64)
        kw = np.empty(k * k, dtype=np.float64)
        for px in range(out.shape[1]):
            n = 0
            for oy in range(k):
                cy = py - oy
                if cy < 0 or cy >= height:
                    continue
                for ox in range(k):
                    cx = px - ox
                    if cx < 0 or cx >= width:
                        continue
                    e = sources[cy, cx, 0]
                    if e < 0:
                        continue
                    sy = sources[cy, cx, 1] + oy
                    sx = sources[cy, cx, 2] + ox
                    w = window_weights[oy, ox]
                    found = False
                    for j in range(n):
                        if ke[j] == e and ky[j] == sy and kx[j] == sx:
                            kw[j] += w
                            found = True
                            break
                    if not found:
                        ke[n] = e
                        ky[n] = sy
                        kx[n] = sx
                        kw[n] = w
                        n += 1
            if n == 0:
                chosen[py, px, 0] = -1
                chosen[py, px, 1] = -1
                chosen[py, px, 2] = -1
                continue
            best = 0
            for j in range(1, n):
                if kw[j] > kw[best]:
                    best = j
            e = ke[best]
            sy = ky[best]
            sx = kx[best]
            for ch in range(channels):
                out[py, px, ch] = exemplar_appearance[e, sy, sx, ch]
            chosen[py, px, 0] = e
            chosen[py, px, 1] = sy
            chosen[py, px, 2] = sx


def vote_mode(
    exemplar_appearance,
    window_weights,
    query_lookup,
    cand_e,
    cand_y,
    cand_x,
    matches,
    out,
    chosen,
):
    """M-step by copying: every padded query pixel takes the exemplar pixel that most of
    its overlapping windows agree on.

    Each window covering a pixel proposes one exemplar pixel (its match shifted by
    the pixel's offset in the window), with its Gaussian window weight. Proposals
    of the same exemplar pixel add up, and the pixel copies the appearance of the
    heaviest (the weighted mode of source positions). Where neighbouring windows
    are matched coherently they agree and the copy is exact; where they disagree
    the boundary between sources falls where the weights change sides, without
    averaging colours. ``chosen`` (Hq + 2r, Wq + 2r, 3) receives the exemplar
    index and *padded* source
    coordinates (-1 where no window covers the pixel).
    """
    sources = _match_sources(query_lookup, cand_e, cand_y, cand_x, matches)
    _run(
        lambda a, b: _vote_mode_rows(
            a, b, exemplar_appearance, window_weights, sources, out, chosen
        ),
        out.shape[0],
        8,
    )


@njit(cache=True, nogil=True)
def _masked_column_sums(bands, channels, mask, centre, sums):
    """Add to ``sums[j]`` ``bands[y, x, channels[j]]`` (``centre`` empty) or its squared
    difference from ``centre[j]``, pixel by pixel in row-major order over the pixels where
    ``mask`` is True (``mask`` empty: every pixel), in the dtype of ``sums``."""
    squared = centre.shape[0] > 0
    masked = mask.shape[0] > 0
    for y in range(bands.shape[0]):
        for x in range(bands.shape[1]):
            if masked and not mask[y, x]:
                continue
            for j in range(channels.shape[0]):
                value = bands[y, x, channels[j]]
                if squared:
                    difference = value - centre[j]
                    sums[j] += difference * difference
                else:
                    sums[j] += value


def masked_std(parts, masks) -> np.ndarray:
    """The standard deviation of each column of the stacked (pixels, columns) array
    ``np.concatenate([np.concatenate([a[..., c] for a, c in p], axis=2)[m] for p, m in
    zip(parts, masks)]).std(axis=0)``, the same values, without gathering it.

    ``parts``: per image, its columns as (array (H, W, C), channel indices) pairs, alike
    for every image; ``masks``: per image, its pixels (bool (H, W); None: all of them).
    NumPy sums two or more columns over the first axis in row order, one after the other
    (pairwise only a single column): these sums are made in that order, in the stacked
    array's dtype, and divided as NumPy's ``_var`` divides (by the count as an intp). The
    engine's band scales at 512^2: 65 ms of gathering and reducing, now about 10."""
    dtype = np.result_type(*(array for image in parts for array, _ in image))
    empty_mask = np.empty((0, 0), dtype=np.bool_)
    count = np.intp(
        sum(
            mask.sum() if mask is not None else image[0][0].shape[0] * image[0][0].shape[1]
            for image, mask in zip(parts, masks, strict=True)
        )
    )
    if sum(len(channels) for _, channels in parts[0]) == 1:  # one column: summed pairwise
        stacked = np.concatenate(
            [
                array[..., channels][mask]
                if mask is not None
                else array[..., channels].reshape(-1, 1)
                for image, mask in zip(parts, masks, strict=True)
                for array, channels in image
            ]
        )
        return stacked.astype(dtype, copy=False).std(axis=0)
    stds = []
    for k in range(len(parts[0])):
        channels = np.ascontiguousarray(parts[0][k][1], dtype=np.int64)
        means = np.zeros(len(channels), dtype=dtype)
        squares = np.zeros(len(channels), dtype=dtype)
        for centre, sums in ((np.empty(0, dtype), means), (means, squares)):
            for image, mask in zip(parts, masks, strict=True):
                _masked_column_sums(
                    image[k][0], channels, empty_mask if mask is None else mask, centre, sums
                )
            np.true_divide(sums, count, out=sums, casting="unsafe")
        stds.append(np.sqrt(squares))
    return np.concatenate(stds)


#: Data cost of a source outside its exemplar: never taken.
_OUTSIDE = 1e9


@njit(cache=True, nogil=True)
def _colour_gap(exemplars, shapes, e1, y1, x1, e2, y2, x2):
    """|colour of source 1 - colour of source 2| (1.0 where either lies outside its exemplar)."""
    if (
        e1 < 0
        or e2 < 0
        or y1 < 0
        or x1 < 0
        or y2 < 0
        or x2 < 0
        or y1 >= shapes[e1, 0]
        or x1 >= shapes[e1, 1]
        or y2 >= shapes[e2, 0]
        or x2 >= shapes[e2, 1]
    ):
        return 1.0
    s = 0.0
    for ch in range(exemplars.shape[3]):
        d = exemplars[e1, y1, x1, ch] - exemplars[e2, y2, x2, ch]
        s += d * d
    return np.sqrt(s)


@njit(cache=True, nogil=True)
def _seam(exemplars, shapes, e, oy, ox, f, fy, fx, y, x, ny, nx, floor):
    """Kwatra et al.'s seam cost between pixel (y, x) labelled (e, oy, ox) and its
    neighbour (ny, nx) labelled (f, fy, fx): the two sources' colour gap on both pixels
    (a distance, so the expansion moves below are exact), plus ``floor`` per seam."""
    if e == f and oy == fy and ox == fx:
        return 0.0
    return (
        floor
        + _colour_gap(exemplars, shapes, e, y + oy, x + ox, f, y + fy, x + fx)
        + _colour_gap(exemplars, shapes, e, ny + oy, nx + ox, f, ny + fy, nx + fx)
    )


@njit(cache=True, nogil=True)
def _data(exemplars, shapes, reference, e, oy, ox, y, x):
    """Squared distance of label (e, oy, ox)'s colour at (y, x) to the reference."""
    sy, sx = y + oy, x + ox
    if e < 0 or sy < 0 or sx < 0 or sy >= shapes[e, 0] or sx >= shapes[e, 1]:
        return _OUTSIDE
    s = 0.0
    for ch in range(exemplars.shape[3]):
        d = exemplars[e, sy, sx, ch] - reference[y, x, ch]
        s += d * d
    return s


@njit(cache=True, nogil=True)
def expansion_terms(
    exemplars,
    shapes,
    inside,
    reference,
    label_e,
    label_y,
    label_x,
    mask,
    region,
    y0,
    x0,
    alpha,
    smooth,
    floor,
    weights,
    data_now,
):
    """The graph of one alpha-expansion move (Boykov, Veksler & Zabih 2001).

    Every object pixel has a label: an exemplar and an offset (source = pixel +
    offset). In the move, each *free* pixel (inside ``region``, a crop whose corner
    is (y0, x0), not labelled ``alpha`` yet, with ``alpha``'s source inside its
    exemplar's object, ``inside``) keeps its label (x = 0) or takes ``alpha``
    (x = 1); all other pixels keep theirs. Costs: the squared distance of the
    copied colour to ``reference``, plus ``smooth`` times the seam costs
    (:func:`_seam`), each seam's also times the mean of its two pixels' ``weights``
    ((H, W)). ``data_now`` (H, W) keeps each pixel's data cost of its own label between
    moves (0: not known yet; gathered here once, then read; :func:`expansion_apply`
    forgets it where a cut changes the label): it only changes where a move changed
    labels, and a pixel is a node of 12-14 moves at 512^2. A pair of free neighbours
    p, q costs E(xp, xq) = a + (c - a) xp - c xq + (b + c - a)(1 - xp) xq with
    a = seam(lp, lq), b = seam(lp, alpha), c = seam(alpha, lq); b + c >= a as the seam
    cost is a distance, so the move is a minimum cut (Kolmogorov & Zabih 2004).

    Returns
    -------
    node : (h, w) int64, the free pixels' node numbers (-1: fixed)
    cost0, cost1 : (n,) the unary costs of keeping the label and of taking alpha
    first, second, capacity : (m,) edges first -> second, paid when first keeps its
        label and second takes alpha
    """
    h, w = region.shape
    height, width = mask.shape
    ae, ay, ax = alpha[0], alpha[1], alpha[2]
    node = np.full((h, w), -1, np.int64)
    n = 0
    for i in range(h):
        for j in range(w):
            y, x = y0 + i, x0 + j
            if not (region[i, j] and mask[y, x]):
                continue
            if label_e[y, x] == ae and label_y[y, x] == ay and label_x[y, x] == ax:
                continue
            sy, sx = y + ay, x + ax
            if sy < 0 or sx < 0 or sy >= shapes[ae, 0] or sx >= shapes[ae, 1]:
                continue
            if not inside[ae, sy, sx]:
                continue
            node[i, j] = n
            n += 1
    # Each free pixel's gap between its own source's colour and alpha's: between two
    # free neighbours with one label (most pairs) both of the move's seams are made of
    # these two gaps, which would otherwise be gathered again for every pair.
    to_alpha = np.empty(n)
    for i in range(h):
        for j in range(w):
            p = node[i, j]
            if p >= 0:
                y, x = y0 + i, x0 + j
                to_alpha[p] = _colour_gap(
                    exemplars,
                    shapes,
                    label_e[y, x],
                    y + label_y[y, x],
                    x + label_x[y, x],
                    ae,
                    y + ay,
                    x + ax,
                )
    cost0 = np.zeros(n)
    cost1 = np.zeros(n)
    first = np.empty(2 * n, np.int64)
    second = np.empty(2 * n, np.int64)
    capacity = np.empty(2 * n)
    m = 0
    for i in range(h):
        for j in range(w):
            p = node[i, j]
            if p < 0:
                continue
            y, x = y0 + i, x0 + j
            e, oy, ox = label_e[y, x], label_y[y, x], label_x[y, x]
            own = data_now[y, x]
            if own == 0.0:  # not known yet (or exactly 0, 0.2 % at 512^2: gathered again)
                own = _data(exemplars, shapes, reference, e, oy, ox, y, x)
                data_now[y, x] = own
            cost0[p] += own
            cost1[p] += _data(exemplars, shapes, reference, ae, ay, ax, y, x)
            for k in range(4):
                ny = y + (1 if k == 0 else -1 if k == 1 else 0)
                nx = x + (1 if k == 2 else -1 if k == 3 else 0)
                if ny < 0 or nx < 0 or ny >= height or nx >= width or not mask[ny, nx]:
                    continue
                f, fy, fx = label_e[ny, nx], label_y[ny, nx], label_x[ny, nx]
                pair = smooth * (0.5 * (weights[y, x] + weights[ny, nx]))
                ci, cj = ny - y0, nx - x0
                q = node[ci, cj] if 0 <= ci < h and 0 <= cj < w else -1
                if q < 0:  # a fixed neighbour keeps its label: a unary term
                    cost0[p] += pair * _seam(
                        exemplars, shapes, e, oy, ox, f, fy, fx, y, x, ny, nx, floor
                    )
                    cost1[p] += pair * _seam(
                        exemplars, shapes, ae, ay, ax, f, fy, fx, y, x, ny, nx, floor
                    )
                elif (k == 0 or k == 2) and e == f and oy == fy and ox == fx:
                    # one label: no seam now, and alpha's seam on either side is the
                    # same (the same two gaps)
                    b = pair * (floor + to_alpha[p] + to_alpha[q])
                    cost1[p] += b
                    cost1[q] -= b
                    first[m] = p
                    second[m] = q
                    capacity[m] = b + b  # both seams' gaps are >= 0: no rounding guard
                    m += 1
                elif k == 0 or k == 2:  # each pair of free pixels once
                    a = pair * _seam(exemplars, shapes, e, oy, ox, f, fy, fx, y, x, ny, nx, floor)
                    b = pair * _seam(exemplars, shapes, e, oy, ox, ae, ay, ax, y, x, ny, nx, floor)
                    c = pair * _seam(exemplars, shapes, ae, ay, ax, f, fy, fx, y, x, ny, nx, floor)
                    cost0[p] += a
                    cost1[p] += c
                    cost1[q] -= c
                    first[m] = p
                    second[m] = q
                    capacity[m] = max(b + c - a, 0.0)  # >= 0 but for rounding
                    m += 1
    return node, cost0, cost1, first[:m], second[:m], capacity[:m]


@njit(cache=True, nogil=True)
def expansion_apply(
    node, takes, labels, ids, changed_at, data_now, y0, x0, alpha, number, move, lost
):
    """Apply one alpha-expansion move's cut (:func:`expansion_terms`' ``node``, (h, w),
    and ``takes``, (n,) bool: the nodes that take ``alpha``), in one pass over the crop
    whose corner is (y0, x0): each such pixel gets ``alpha`` in ``labels`` (label_e,
    label_y, label_x), ``number`` in ``ids``, ``move`` in ``changed_at`` and 0 in
    ``data_now`` (its data cost not known: :func:`expansion_terms` gathers it when next
    needed), and the label it had (``ids``, 1-based) one pixel less in ``lost``. Returns
    the number of pixels that took ``alpha``.
    """
    label_e, label_y, label_x = labels
    h, w = node.shape
    count = 0
    for i in range(h):
        for j in range(w):
            p = node[i, j]
            if p < 0 or not takes[p]:
                continue
            y, x = y0 + i, x0 + j
            lost[ids[y, x] - 1] += 1
            ids[y, x] = number
            changed_at[y, x] = move
            data_now[y, x] = 0.0
            label_e[y, x] = alpha[0]
            label_y[y, x] = alpha[1]
            label_x[y, x] = alpha[2]
            count += 1
    return count


@njit(cache=True, nogil=True)
def nearest_host_distance(colours, host, cell_y, cell_x):
    """Each pixel's smallest colour distance to the host colours of its low-resolution
    cell (``cell_y[y]``, ``cell_x[x]``) and of the eight cells around it (clipped).

    A pass over the pixels instead of nine full-size gathers of the hosts; float32
    throughout, as the arrays are.
    """
    height, width, channels = colours.shape
    rows, columns = host.shape[0], host.shape[1]
    out = np.empty((height, width), np.float32)
    for y in range(height):
        for x in range(width):
            best = np.float32(np.inf)
            for dy in range(-1, 2):
                hy = min(max(cell_y[y] + dy, 0), rows - 1)
                for dx in range(-1, 2):
                    hx = min(max(cell_x[x] + dx, 0), columns - 1)
                    s = np.float32(0.0)
                    for c in range(channels):
                        d = colours[y, x, c] - host[hy, hx, c]
                        s += d * d
                    best = min(best, s)
            out[y, x] = np.sqrt(best)
    return out
