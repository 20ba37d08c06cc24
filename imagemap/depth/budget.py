"""Memory and time of a colorization, estimated from the sizes before it starts.

The engine's memory at a pyramid level is dominated by the PCA window features of
every query window centre and every exemplar candidate (``2 * D`` bytes each: int16,
D the feature dimension: a fifth of the 2 k^2 guide and 3 k^2 appearance window
values, plus position and exemplar cost), by the per-pixel arrays of the query
(padded bands, lookup tables, vote buffers, the dense source map) and of the
exemplars, and by the previous (coarser) level's solver, still alive while the
next one is built. :func:`estimate_colorize` adds these up per level and scales
them by factors measured against peak resident memory (``VmHWM``) of real runs
(see ``CALIBRATION``); the time is proportional to window centres times feature
dimension, also measured.

:func:`guard_colorize` (called by :func:`imagemap.colorize` and ``imagemap
synthesize``) refuses a run whose estimate exceeds the memory available now
(``MemAvailable`` of ``/proc/meminfo``, or a cgroup limit), with the estimate and
the way out. Switch it off with ``imagemap synthesize --no-memory-check``, with
``with imagemap.depth.budget.memory_check(False): ...`` in Python, or with the
environment variable ``IMAGEMAP_NO_MEMORY_CHECK=1``.
"""

from __future__ import annotations

import contextlib
import contextvars
import logging
import os
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, replace

import numpy as np

from imagemap import memory
from imagemap.depth.config import resolve_config
from imagemap.depth.guides import CROP_SLACK, sized_pyramid

__all__ = [
    "Estimate",
    "MemoryBudgetError",
    "available_memory",
    "estimate_colorize",
    "guard_colorize",
    "memory_check",
]

log = logging.getLogger("imagemap")

# Bytes per item beside the features (see the module docstring), and the measured
# factors. CALIBRATION: fitted on fish runs (queries 150x200 to 2400x3200, examples
# 150x200 and 360x480, m = 2, patchmatch) against VmHWM - VmRSS before the call; refitted
# for int16 features and one packed copy of the exemplar bands: -1 % to +15 % from 300x400
# to 2400x3200 (1820 MB measured, 1807 MB estimated), -7 % at 150x200. Examples as large as
# the query (1024^2 to 4096^2 fish) are overestimated by 15-25 %. Refitted (issue 14, round
# two) once the front end's pyramid levels were freed as the engine packs them: in-process
# VmHWM - VmRSS before the call, fish, m = 2 unless said: 200x150 91 MB measured / 87
# estimated, 512^2 156 / 135, 1024^2 260 / 295 (m = 1: 244 / 281), 2048^2 789 / 930, a
# 2000x1500 query with 200x150 examples 572 / 627 (-14 % to +18 %). Refitted (issue 14,
# round three) once the bands were packed for the box around the object's windows only and
# the copy finish worked a channel and a side at a time, the same measure: 200x150 82 MB
# measured / 86 estimated, 512^2 154 / 125, 1024^2 242 / 255 (m = 1: 196 / 229), 2048^2
# 650 / 771, the 2000x1500 query with 200x150 examples 385 / 451 (-19 % to +19 %).
# Checked (#44 item 3) in fresh processes (benchmarks/memory.py, VmHWM minus VmRSS before
# the call, fish, m = 2) once the seams stage's peak came down: 1024^2 241 MB measured /
# 254 estimated, 2048^2 726 / 766, 4096^2 2702 / 2805 (+4 % to +5 %; no refit needed).
# Examples cut to their objects (#44 item 3, guides.crop_levels): the exemplar terms take
# the crop's box (about, _crop_shape) for the frame, and the PatchMatch lookup is held for
# the box too: 1024^2 220 MB measured / 248 estimated, 2048^2 668 / 745 (+13 %, +12 %; with
# the frames 254 and 766). Not refitted: an upper bound within the +-25 % tests/test_memory.py
# allows, and 4096^2 was not re-measured.
_QUERY_CENTRE_BYTES = 55  # coordinates (frame and packed), positions, matches, costs
_CANDIDATE_BYTES = 40  # exemplar index, coordinates, position, bias
_QUERY_PIXEL_BYTES = 60  # lookup, vote buffers, dense maps, the copy finish
_FEATURE_BYTES = 2  # per feature dimension: int16 (EngineParams.quantize_features)
# Lookups, valid masks (the packed bands, for the object's box, in the candidate terms).
_EXEMPLAR_PIXEL_BYTES = 10
_QUERY_LEVEL_BYTES = 13  # a level of the query's pyramid: guide bands, mask
_EXEMPLAR_LEVEL_BYTES = 25  # a level of an example's pyramid: guide and colour bands, mask
# numba kernels and lazily imported modules on first use: 80 MB until `imagemap synthesize`
# loaded its kernels without numba's registries (imagemap.cli.lean_kernel_loads, 16-19 MB
# less at 1024^2; a library call still loads them: this estimate is then that much low).
_OVERHEAD_BYTES = 64 * 2**20
_REGISTRY_BYTES = 16 * 2**20  # numba's registries, which the mesh route still loads
_MEMORY_FACTOR = 0.8
# Seconds per window centre and feature dimension, all iterations, the whole pipeline
# (engine and finish) in one figure, from fresh-process runs of benchmarks/memory.py
# (generated fish, m = 2). 2026-11-29, after the speed round (REFINE_PASSES, the PatchMatch
# early stop), quiet machine (load 0.2-1.2): 11.4 / 40.2 / 178.1 s of wall time and 13.1 /
# 48.1 / 218.2 s of CPU at 1024^2, 2048^2 and 4096^2; 7.5e-7 gives 13.7 / 48.7 / 186.6 s
# (wall +20 %, +21 %, +5 %; CPU +5 %, +1 %, -14 %). The 1.4e-6 before it (2026-11-28, CPU at
# load 4-5 of the code before the round) erred long by 2x on these runs.
# Refitted after the third round (2026-11-29: the engine on both cores, the search size),
# quiet machine (load 0.8-1.0): 10.5 / 17.4 / 49.3 s of wall time and 12.5 / 19.4 / 50.2 s of
# CPU at 1024^2, 2048^2 and 4096^2 (the last two above the search size). Both time constants
# scaled by 0.85 from 7.5e-7 and 1.0e-6: 11.7 / 20.0 / 44.9 s (wall +11 %, +15 %, -9 %; CPU
# -7 %, +3 %, -11 %).
# Refitted after the sixth round (2026-11-29: the stages around the engine, the seams' own
# max-flow), quiet machine (load 1.0-1.1): 8.5 / 15.1 s and 48.2 / 39.3 s (two runs) of wall
# time at 1024^2, 2048^2 and 4096^2, against 11.8 / 20.1 / 45.0 s estimated (1.38, 1.33 over).
# 6.4e-7 scaled by 0.75: 8.9 / 17.2 / 42.1 s (+5 %, +14 %, -13 % / +7 %).
# Refitted after the ninth round (2026-11-29: the stages around the engine and the seams
# faster, the full-size pose and selection cheaper), load 1.1-1.3, one run each: 7.87 / 12.7
# / 34.5 s of wall time at 1024^2, 2048^2 and 4096^2, against 8.9 / 17.2 / 42.1 s estimated
# (1.13, 1.36, 1.22 over; CPU 11.3 / 15.5 / 37.3 s). The full-size stages alone had sped up:
# _SECONDS_PER_FULL_PIXEL 0.85e-6 -> 0.6e-6 gives 8.9 / 14.8 / 32.4 s (wall +13 %, +16 %,
# -6 %; CPU -22 %, -5 %, -13 %).
_SECONDS_PER_FEATURE = 4.8e-7
_SECONDS_OVERHEAD = 0.3

# Above the search size (pyramid.search_size), the full-size finish: bytes per query pixel
# (sources, the map and its reference, the blend's solve, the pose undone) and per example
# pixel (its colours, copied from at full size), and seconds per pixel of either (the
# full-size stages: select, pose, averaging, the finish). Fresh-process runs of
# benchmarks/memory.py (generated fish, m = 2, 2026-11-29, load 8.5-9.6): 2048^2 483 MB
# added, 25.0 s of CPU (two runs), 4096^2 1680 MB, 56.7 s; these give 485 MB, 23.5 s and
# 1701 MB, 52.8 s (+0 %, -6 %; +1 %, -7 %). The peak is the full-size blend's.
# #44 fifth round: the examples' full-size depth is no longer held through the blend
# (pipeline.ExampleFrame): 12 bytes per example pixel (their colours), not 16. With the
# overhead above and the database's cached depths dropped (colorize_estimate), 2026-11-29,
# benchmarks/memory.py, load 5-6: 1024^2 188 MB added / 224 estimated, 2048^2 381 / 416,
# 4096^2 1297 / 1471 (+19 %, +9 %, +13 %).
# #44 item 3, the 4096^2 peak round: the blend holds about three full-size float64 arrays
# less (poisson.seamless_copy), the pose resamples by blocks of rows; benchmarks/memory.py,
# 2026-11-29, load 4.5-5: 2048^2 387 MB added, 4096^2 1193 (the fine stage's 1166 beside
# it); 80 -> 70 bytes a query pixel gives 376 / 1303 MB (-3 %, +9 %; 80 gave +8 %, +23 %).
_FULL_PIXEL_BYTES = 70
_FULL_EXAMPLE_PIXEL_BYTES = 12
_SECONDS_PER_FULL_PIXEL = 0.6e-6  # refitted with _SECONDS_PER_FEATURE above

#: Runs estimated to take longer than this are announced with a warning (not refused).
LONG_RUN_SECONDS = 300.0

_CHECK = contextvars.ContextVar("imagemap_memory_check", default=True)


#: A run whose estimated memory exceeds what this process may use (one type for every
#: guard: :class:`imagemap.memory.MemoryBudgetError`).
MemoryBudgetError = memory.MemoryBudgetError


@dataclass(frozen=True)
class Estimate:
    """Estimated peak memory (bytes added by the run) and time (seconds) of a colorization."""

    bytes: int
    seconds: float
    levels: int
    query_centres: int
    candidates: int

    def describe(self) -> str:
        return f"about {_format_bytes(self.bytes)} and {_format_seconds(self.seconds)}"


def _format_bytes(n: float) -> str:
    if n >= 2**30:
        return f"{n / 2**30:.1f} GB"
    return f"{n / 2**20:.0f} MB"


def _format_seconds(s: float) -> str:
    if s >= 3600:
        return f"{s / 3600:.1f} h"
    if s >= 120:
        return f"{s / 60:.0f} min"
    return f"{s:.0f} s" if s >= 10 else f"{s:.1f} s"


def _feature_dims(k: int, pca_fraction: float, guide_bands: int = 2, appearance_bands: int = 3):
    guide = max(1, int(round(pca_fraction * guide_bands * k * k)))
    appearance = max(1, int(round(pca_fraction * appearance_bands * k * k)))
    return guide + appearance + 3


def averaging_factor(size: float, search_size: float, align: int) -> int:
    """The power of two (at most ``align``) by which an object ``size`` pixels across (the
    square root of its area) is block-averaged for the synthesis: the smallest that
    brings it to ``search_size`` or less; 1 when it is no larger or ``search_size`` is 0
    (the pipeline's ``working`` stage, and the estimate before any work).

    Examples
    --------
    >>> averaging_factor(1724.0, 640.0, 32), averaging_factor(431.0, 640.0, 32)
    (4, 1)
    """
    factor = 1
    while search_size > 0 and size / factor > search_size and factor * 2 <= align:
        factor *= 2
    return factor


def _working_factor(foreground: int, search_size: float, levels: int) -> int:
    """The block-averaging factor of a query with ``foreground`` object pixels (the
    object's size taken here in the query's pixels, not the synthesis frame's)."""
    return averaging_factor(float(np.sqrt(foreground)), search_size, 2 ** (levels - 1))


def _boundary(mask: np.ndarray) -> int:
    """Pixels on the mask's border (vertical plus horizontal transitions)."""
    return int(
        np.count_nonzero(mask[1:] != mask[:-1]) + np.count_nonzero(mask[:, 1:] != mask[:, :-1])
    )


def estimate_colorize(
    shape: tuple[int, int],
    foreground: int,
    boundary: int,
    exemplars: Sequence[tuple[tuple[int, int], int, int]],
    patch_sizes: Sequence[int],
    pca_fraction: float = 0.2,
    guide_bands: int = 2,
    search_size: float = 0.0,
) -> Estimate:
    """Estimate peak memory and time of a colorization from sizes alone.

    Parameters
    ----------
    shape : (H, W)
        The query depth's shape.
    foreground, boundary : int
        The query's object pixels and border pixels (see :func:`guard_colorize`).
    exemplars : sequence of ((H, W), foreground, boundary)
        The examples the run will use.
    patch_sizes : sequence of int
        Window width per level, fine to coarse (as many as the run's levels).
    pca_fraction : float
        Fraction of the PCA basis kept.
    guide_bands : int
        Guide bands per pixel (depth, its detail, and the silhouette band if on).
    search_size : float
        ``pyramid.search_size``: above it the engine and the seams run on the query and
        examples block-averaged (their estimate, with the coarser levels' windows), and
        the full-size finish (the copy's sources and colours, the blend, the pose
        undone) is estimated per full-size pixel; 0: no cap.
    """
    factor = _working_factor(foreground, search_size, len(patch_sizes))
    if factor > 1:
        skipped = factor.bit_length() - 1  # the finest levels, not searched
        working = estimate_colorize(
            (-(-shape[0] // factor), -(-shape[1] // factor)),
            foreground // factor**2,
            boundary // factor,
            [
                ((-(-h // factor), -(-w // factor)), f // factor**2, b // factor)
                for (h, w), f, b in exemplars
            ],
            patch_sizes[skipped:],
            pca_fraction,
            guide_bands,
        )
        pixels = shape[0] * shape[1]
        example_pixels = sum(h * w for (h, w), _, _ in exemplars)
        finish = _FULL_PIXEL_BYTES * pixels + _FULL_EXAMPLE_PIXEL_BYTES * example_pixels
        return replace(
            working,
            bytes=int(max(working.bytes, _OVERHEAD_BYTES + finish)),
            seconds=working.seconds + _SECONDS_PER_FULL_PIXEL * (pixels + example_pixels),
        )
    height, width = shape
    n_ex = len(exemplars)
    ex_h = max((e[0][0] for e in exemplars), default=0)
    ex_w = max((e[0][1] for e in exemplars), default=0)
    per_level = []
    work = 0.0
    persistent = 0.0
    for level, k in enumerate(patch_sizes):
        scale = 2**level
        r = k // 2
        dims = _feature_dims(k, pca_fraction, guide_bands)
        pixels = (height / scale + 2 * r) * (width / scale + 2 * r)
        centres = min(pixels, foreground / scale**2 + r * boundary / scale)
        candidates = sum(f / scale**2 + r * b / scale for _, f, b in exemplars)
        ex_pixels = n_ex * (ex_h / scale + 2 * r) * (ex_w / scale + 2 * r)
        solver = (
            centres * (_FEATURE_BYTES * dims + _QUERY_CENTRE_BYTES)
            + candidates * (_FEATURE_BYTES * dims + _CANDIDATE_BYTES)
            + pixels * _QUERY_PIXEL_BYTES
            + ex_pixels * _EXEMPLAR_PIXEL_BYTES
        )
        # The front end's pyramid level, alive until the engine has packed it.
        pyramid = (
            height * width * _QUERY_LEVEL_BYTES + n_ex * ex_h * ex_w * _EXEMPLAR_LEVEL_BYTES
        ) / scale**2
        per_level.append((solver, centres, candidates, pyramid))
        work += centres * dims
        persistent += 40 * height * width / scale**2
    # At level l the finer levels of the pyramids are still held (each is dropped once
    # packed); the coarser level's solver is freed before this one is built.
    peak = max(
        per_level[i][0] + sum(level[3] for level in per_level[:i]) for i in range(len(per_level))
    )
    total = _OVERHEAD_BYTES + _MEMORY_FACTOR * (peak + persistent)
    return Estimate(
        bytes=int(total),
        seconds=_SECONDS_OVERHEAD + _SECONDS_PER_FEATURE * work,
        levels=len(patch_sizes),
        query_centres=int(per_level[0][1]),
        candidates=int(per_level[0][2]),
    )


#: The address space (VmSize) of a process once the engine has run: its modules, numba's
#: kernels and thread pool (each thread's stack and allocator arena). Measured after a
#: 200x150 synthesis: 563, 707, 852 and 1,140 MB with 1, 2, 4 and 8 numba threads (469 MB
#: before); bounded by 600 MB + 75 MB per thread. Under ``ulimit -v`` the guard counts
#: this much as taken before the run's own arrays: at 900 MB a 2000x1500 query passed the
#: guard (VmSize at the guard: about 300 MB) and failed with a MemoryError in the engine.
_ENGINE_ADDRESS_SPACE = 600 * 2**20
_THREAD_ADDRESS_SPACE = 75 * 2**20


def _engine_address_space() -> int:
    threads = os.environ.get("NUMBA_NUM_THREADS", "")
    count = int(threads) if threads.isdigit() else (os.cpu_count() or 1)
    return _ENGINE_ADDRESS_SPACE + _THREAD_ADDRESS_SPACE * max(count, 1)


def available_memory() -> int | None:
    """Bytes this process can still use: the smallest of MemAvailable, a cgroup's room (v1 or
    v2) and ``RLIMIT_AS``'s room (``ulimit -v``, where an allocation past it fails at once
    whatever the machine has free; counted from the address space the engine will have
    mapped, not only what is mapped now); None when none is known. See
    :func:`imagemap.memory.available_memory`."""
    return memory.available_memory(mapped_at_least=_engine_address_space())


@contextlib.contextmanager
def memory_check(enabled: bool = True) -> Iterator[None]:
    """Switch the memory guard on or off inside a ``with`` block.

    Examples
    --------
    >>> with memory_check(False):  # doctest: +SKIP
    ...     result = imagemap.colorize(huge_depth, db)
    """
    token = _CHECK.set(bool(enabled))
    try:
        yield
    finally:
        _CHECK.reset(token)


def _enabled() -> bool:
    return _CHECK.get() and memory._enabled()  # and IMAGEMAP_NO_MEMORY_CHECK unset or 0


def colorize_estimate(depth: np.ndarray, database, config, examples=None) -> Estimate:
    """The :func:`estimate_colorize` of ``imagemap.colorize(depth, database, config, ...)``.

    ``config`` is a :class:`~imagemap.depth.config.DepthConfig` (or a preset name).
    Without ``examples`` the ``m`` largest examples stand for the automatic selection
    (an upper bound).
    """
    config = resolve_config(config)
    n = config.selection.m
    guide_bands = 2 + (1 if config.guides.silhouette_weight else 0)
    mask = np.asarray(depth) > 0
    pyramid = sized_pyramid(mask, replace(config.pyramid, grow=True))
    if examples:
        chosen = [database[name] for name in examples]
    else:
        sizes = [e.depth.size for e in database]
        order = np.argsort(sizes, kind="stable")[::-1][: max(1, min(n, len(database)))]
        chosen = [database[int(i)] for i in order]
    # The engine gets each example cut to its object and margin (guides.crop_levels).
    crop = (2 * (max(pyramid.patch_sizes) // 2) + CROP_SLACK) * 2 ** (len(pyramid.patch_sizes) - 1)
    exemplars = [(_crop_shape(e.mask, crop), int(e.mask.sum()), _boundary(e.mask)) for e in chosen]
    estimate = estimate_colorize(
        mask.shape,
        int(mask.sum()),
        _boundary(mask),
        exemplars,
        pyramid.patch_sizes,
        config.matching.pca_fraction,
        guide_bands,
        config.pyramid.search_size,
    )
    if getattr(database, "keep_arrays", True):
        return estimate
    # One query (Database(keep_arrays=False)): the arrays the database holds now are
    # dropped once the synthesis has posed its examples, below what the process holds.
    released = database.releasable_bytes()
    return replace(estimate, bytes=max(estimate.bytes - released, _OVERHEAD_BYTES))


def _crop_shape(mask: np.ndarray, margin: int) -> tuple[int, int]:
    """(H, W) of the box of ``mask`` and ``margin`` pixels around it, inside the frame: about
    an example's crop (:func:`imagemap.depth.guides.crop_levels`)."""
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    if len(rows) == 0:
        return mask.shape
    height, width = mask.shape
    return (
        min(int(rows[-1]) + 1 + margin, height) - max(int(rows[0]) - margin, 0),
        min(int(cols[-1]) + 1 + margin, width) - max(int(cols[0]) - margin, 0),
    )


def guard_colorize(
    depth: np.ndarray,
    database,
    config=None,
    examples=None,
    what: str = "the query",
    check: bool | None = None,
) -> Estimate | None:
    """Estimate a colorization; log it (``-v``) and refuse it if it cannot fit in memory.

    ``check`` None follows :func:`memory_check` and ``IMAGEMAP_NO_MEMORY_CHECK``
    (when they switch the guard off, nothing is estimated and None is returned);
    True or False estimates and logs, and refuses only if True.

    Raises
    ------
    MemoryBudgetError
        The estimate exceeds :func:`available_memory`; the message gives the estimate
        and the way out (a smaller depth map, fewer examples, ``--no-memory-check``).
    """
    if check is None:
        if not _enabled():
            return None
        check = True
    depth = np.asarray(depth)
    if depth.ndim != 2 or len(database) == 0:
        return None  # the colorization's own checks say what is wrong
    estimate = colorize_estimate(depth, database, config, examples)
    log.info(
        "estimate for %s (%dx%d, %d levels): %s",
        what,
        depth.shape[1],
        depth.shape[0],
        estimate.levels,
        estimate.describe(),
    )
    if estimate.seconds > LONG_RUN_SECONDS:
        log.warning(
            "%s (%dx%d) will take %s (estimated); a smaller depth map is much faster",
            what,
            depth.shape[1],
            depth.shape[0],
            estimate.describe(),
        )
    available = available_memory()
    if check and available is not None and estimate.bytes > available:
        side = max(depth.shape)
        fit = max(1, int(side * (max(available - _OVERHEAD_BYTES, 0) / estimate.bytes) ** 0.5))
        raise MemoryBudgetError(
            f"{what} ({depth.shape[1]}x{depth.shape[0]}) needs {estimate.describe()}, but only "
            f"{_format_bytes(available)} of memory is available: use a smaller depth map "
            f"(longest side about {fit} pixels or less would fit), fewer or smaller examples "
            "(--m 1), or run anyway with --no-memory-check "
            "(Python: with imagemap.depth.budget.memory_check(False))"
        )
    return estimate


# The mesh route, measured as VmHWM of ``imagemap synthesize MESH -o out.glb`` (a 10,560-face
# fish against five fish meshes): one view at 400x300 355 MB, 800x600 656 MB, so 856 bytes
# per pixel of a view (render, synthesis and the view's results); the bake, two views at
# 100x75: texture 2048^2 1.09 GB, 4096^2 3.55 GB, so 195 bytes per texel.
_VIEW_PIXEL_BYTES = 860
_KEPT_VIEW_PIXEL_BYTES = 60  # each finished view's map, source map and render, kept
_TEXEL_BYTES = 200


def estimate_mesh(size: tuple[int, int], views: int, texture_size: int) -> int:
    """Estimated peak bytes of a mesh synthesis: ``views`` views of ``size`` (W, H), baked
    into a ``texture_size``^2 atlas (see the measurements above).

    Examples
    --------
    >>> round(estimate_mesh((800, 600), 1, 512) / 2**20)
    524
    >>> estimate_mesh((20000, 20000), 1, 512) > 300 * 2**30
    True
    """
    pixels = int(size[0]) * int(size[1])
    return int(
        _OVERHEAD_BYTES
        + _REGISTRY_BYTES
        + pixels * (_VIEW_PIXEL_BYTES + _KEPT_VIEW_PIXEL_BYTES * max(views - 1, 0))
        + int(texture_size) ** 2 * _TEXEL_BYTES
    )


def guard_mesh(
    size: tuple[int, int],
    views: int,
    texture_size: int,
    what: str = "the mesh",
    check: bool | None = None,
) -> int | None:
    """Refuse a mesh synthesis whose estimate (:func:`estimate_mesh`) exceeds the memory this
    process may use (:func:`available_memory`: RLIMIT_AS and cgroup limits included).

    ``check`` None follows :func:`memory_check` and ``IMAGEMAP_NO_MEMORY_CHECK``; False
    estimates and logs only. Returns the estimate (None when switched off).

    Raises
    ------
    MemoryBudgetError
        Naming ``--size`` and ``--texture-size`` and the way out.
    """
    if check is None:
        if not _enabled():
            return None
        check = True
    needed = estimate_mesh(size, views, texture_size)
    log.info(
        "estimate for %s (%d view(s) at %dx%d, texture %d): %s",
        what,
        views,
        size[0],
        size[1],
        texture_size,
        _format_bytes(needed),
    )
    available = available_memory()
    if check and available is not None and needed > available:
        raise MemoryBudgetError(
            f"{what}: {views} view(s) at --size {size[0]}x{size[1]} and --texture-size "
            f"{texture_size} need about {_format_bytes(needed)}, but only "
            f"{_format_bytes(available)} of memory is available: use a smaller --size or "
            "--texture-size, fewer --views, or run anyway with --no-memory-check"
        )
    return needed
