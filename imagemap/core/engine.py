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
>>> params = EngineParams(levels=uniform_levels((5,)), backend="exact", guide_weights=(1.0,),
...                       appearance_weights=(1.0,))
>>> result = synthesize([query], [[exemplar]], params)
>>> result.appearance[0].shape
(32, 32, 1)
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

from imagemap.core.mapping import Mapping, ReleasableLevels
from imagemap.core.params import (
    APPEARANCE_PYRAMIDS,
    BACKENDS,
    VOTES,
    EngineParams,
    LevelPlan,
    uniform_levels,
)
from imagemap.core.pyramid import collapse_laplacian, expand
from imagemap.core.solver import FINAL_RESEED_WORST, LevelSolver, Timer, trim_heap
from imagemap.progress import progress

__all__ = [
    "APPEARANCE_PYRAMIDS",
    "BACKENDS",
    "VOTES",
    "EngineParams",
    "EngineResult",
    "LevelPlan",
    "Mapping",
    "ReleasableLevels",
    "synthesize",
    "uniform_levels",
]

log = logging.getLogger("imagemap")

#: The levels, from the finest, that give the heap's free pages back
#: (:func:`~imagemap.core.solver.trim_heap`) before and after their features and after
#: their E-steps; no other trim. A call's peak is the features of one of them (the PCA
#: samples and feature blocks beside every band): the finest level's at 512^2, the next
#: one's at 200x150, whose windows are the widest of the default plan (11 x 11, against 7
#: x 7 at the finest). A trim just before them gives back every page freed until then
#: (the front end's, the coarser levels'): the trims at the start and at the coarser
#: levels lowered no peak, and each was paid for again in page faults when the next phase
#: took its pages back. Side-by-side task, an engine call's minor faults and the process's
#: peak, trims as before -> these: 512^2 46-47k -> 29-32k, 292-301 -> 291-301 MB; 200x150
#: 22-23k -> 21k, 192-193 -> 193-194 MB. The finest level alone: 512^2 17-20k faults,
#: but 200x150 peaked at 196-197 MB.
TRIMMED_LEVELS = 2


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
    copy_source : ndarray of int32, shape (H, W, 3), or None
        With ``vote="copy"`` or ``"mode"``, per pixel of the finest level: the exemplar
        pixel most of its windows agree on (the weighted mode of their estimates'
        sources), for front ends that copy pixels instead of voting them; None with
        ``vote="mean"``.
    """

    appearance: list[np.ndarray]
    source: np.ndarray
    cost: np.ndarray
    objective: list[list[float]]
    timings: dict[str, float] = field(default_factory=dict)
    backend: str = ""
    copy_source: np.ndarray | None = None


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
    plans = params.level_plans(n_levels)  # raises when there are too few
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
            # Crops of the frame (Mapping.origin) aligned from level to level: a coarser
            # level's colours are expanded onto the finer crop as onto the frame.
            if level > 0 and tuple(levels[level - 1].origin) != (
                2 * ex.origin[0],
                2 * ex.origin[1],
            ):
                raise ValueError(
                    f"exemplar {i}: the crop of level {level - 1} is not twice level {level}'s"
                )
    n_appearance = exemplar_levels[0][0].appearance.shape[2]
    if len(params.appearance_weights) != n_appearance:
        raise ValueError(f"{n_appearance} appearance bands need as many appearance weights")
    for level, plan in enumerate(plans):
        if plan.context_weights and len(plan.context_weights) != n_appearance:
            raise ValueError(
                f"level {level}: {n_appearance} appearance bands need as many context weights"
            )
        if plan.exemplar_costs and len(plan.exemplar_costs) != len(exemplar_levels):
            raise ValueError(
                f"level {level}: {len(exemplar_levels)} exemplars need as many exemplar_costs"
            )
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
    # SciPy's own OpenBLAS (the PCA's eigh) loaded before the limit below, so that the
    # limit covers it too (threadpoolctl limits the libraries loaded)
    import scipy.linalg  # deferred: start-up: only a synthesis fits a PCA  # noqa: F401

    with threadpool_limits(limits=1, user_api="blas"):
        return _synthesize(query_levels, exemplar_levels, params, seed, quiet)


def _synthesize(query_levels, exemplar_levels, params, seed, quiet) -> EngineResult:
    rng = np.random.default_rng(seed)
    timer = Timer()
    n_levels = len(query_levels)
    n_appearance = exemplar_levels[0][0].appearance.shape[2]
    log.info("search backend: %s", params.backend)
    appearance_levels: list[np.ndarray] = [None] * n_levels  # type: ignore[list-item]
    objective: list[list[float]] = [[] for _ in range(n_levels)]
    coarse_source: np.ndarray | None = None
    solver = None
    matches = None
    plans = params.level_plans(n_levels)
    # Only the bands some level weights as context are collapsed and matched (luma alone
    # in the depth front end: one band of three). The colours are a running collapse from
    # the coarsest level, kept at every level but the finest when any level has context.
    with_context = [plan.context_weights for plan in plans[:-1] if plan.has_context]
    context_bands: Any = np.flatnonzero(np.any(with_context, axis=0)) if with_context else []
    kind = params.appearance_pyramid
    # Running collapses of the coarser levels' colours (None until the coarsest is done).
    query_colours: Any = None
    exemplar_colours: Any = None
    for level in progress(range(n_levels - 1, -1, -1), total=n_levels, desc="levels", quiet=quiet):
        exemplars = [levels[level] for levels in exemplar_levels]
        plan = plans[level]
        level_colours: Any = None
        if len(context_bands) and level > 0:  # this level's colours: the next finer's context
            level_colours = [
                _coarse_colours(colours, ex.appearance[..., context_bands], kind)
                for ex, colours in zip(
                    exemplars, exemplar_colours or [None] * len(exemplars), strict=True
                )
            ]
        smallest = min(min(e.frame) for e in exemplars)  # of the frames, not of crops
        k = min(plan.patch_size, smallest - (1 - smallest % 2))
        solver = None  # the coarser level's solver is done: free it before building this one
        level_params = params
        if plan.position_weight is not None:
            level_params = replace(level_params, position_weight=plan.position_weight)
        if plan.patchmatch_passes is not None:
            level_params = replace(level_params, patchmatch_passes=plan.patchmatch_passes)
        if plan.search_radius is not None:
            level_params = replace(level_params, search_radius=plan.search_radius)
        query = query_levels[level]
        context = None
        if plan.has_context and level < n_levels - 1:
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
                guide_weights=params.guide_weights
                + tuple(plan.context_weights[b] for b in context_bands),
            )

        def release(e: int, level: int = level, context=context) -> None:
            # Exemplar e's bands are packed: its mapping and context are not needed any
            # more. Pyramids handed over (ReleasableLevels) drop the level now, before
            # the next exemplar is packed.
            if context is not None:
                context[1][e] = None
            if isinstance(exemplar_levels[e], ReleasableLevels):
                exemplar_levels[e].release(level)

        solver = LevelSolver(
            query,
            exemplars,
            k,
            level_params,
            rng,
            timer,
            False,
            context,
            release,
            exemplar_costs=plan.exemplar_costs,
        )
        # The query's bands are packed too: the mapping goes before the features are made.
        del query, exemplars, context, release  # (release holds the context too)
        exemplar_colours = level_colours
        if isinstance(query_levels, ReleasableLevels):
            query_levels.release(level)
        # The coarser level's matches propagated from the packed lookups alone (no random
        # number drawn): before the features, so that its transients do not add to them.
        propagated: Any = None if coarse_source is None else solver.propagate(coarse_source)
        coarse_source = None
        # The heap's free pages are given back around the features of the TRIMMED_LEVELS
        # finest levels only; at the coarser levels the freed pages stay for the next.
        if level < TRIMMED_LEVELS:
            trim_heap()
        solver.prepare(rng)
        if level < TRIMMED_LEVELS:
            trim_heap()  # the PCA's and the feature blocks' temporaries, before the E-steps
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
            if plan.guide_reseed > 0:
                matches = solver.reseed(matches, plan.guide_reseed, level_seed, rng)
        appearance = solver.vote(matches, appearance)
        previous = np.inf
        for iteration in range(plan.max_iterations):
            # No heap trim between the E-steps and M-steps: their temporaries are few
            # since the choice is one kernel pass (a candidate per centre and its cost),
            # the same sizes every iteration; trimmed, they were faulted back in each
            # time (512^2: 8k of 42k page faults an engine call) for no lower peak (512^2
            # and 1024^2 whole processes 232-235 and 327-330 MB either way).
            solver.set_appearance(appearance)
            candidates = solver.search(
                matches, init=False, seed=level_seed + 1 + iteration, rng=rng
            )
            # A new candidate replaces the match where its exact cost is lower.
            matches = np.ascontiguousarray(matches, dtype=np.int64)
            chosen_cost, changed = solver.choose(matches, candidates)
            value = float(chosen_cost.mean(dtype=np.float64))
            del candidates, chosen_cost  # freed before the M-step
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
                changed,
            )
            if not changed or previous - value < params.tolerance * abs(previous):
                break
            previous = value
        if plan.final_reseed > 0:
            matches = solver.reseed(
                matches,
                plan.final_reseed,
                level_seed + 1 + plan.max_iterations,
                rng,
                worst=FINAL_RESEED_WORST,
                keep_detail=True,
                free=plan.final_reseed_any_exemplar,
            )
            if level > 0:  # the finer levels start from these matches and see their colours
                appearance = solver.vote(matches, appearance)
        if level == 0:  # the finest level's exact costs, while the bands are there
            solver.set_appearance(appearance, project=False)
            final_cost = solver.costs(matches)
        solver.release_search()  # what only the E-step needs, before the dense maps
        if level < TRIMMED_LEVELS:
            trim_heap()  # the E-steps' state, before the dense maps and the next stages
        r = solver.r  # the level's estimate copied out once the E-step's state is freed
        appearance_levels[level] = np.ascontiguousarray(appearance[r : r + h, r : r + w])
        if len(context_bands) and level > 0:
            query_colours = _coarse_colours(
                query_colours, appearance_levels[level][..., context_bands], kind
            )
        coarse_source = solver.dense_source(matches)
    assert solver is not None and matches is not None
    copy_source = None
    if params.vote == "mode":
        copy_source = coarse_source
    elif params.vote == "copy":  # the mode of the final matches' sources, for the copy
        # The padded estimate is not needed any more (its interior was copied into
        # appearance_levels, unless there is no padding): the mode vote may overwrite it.
        scratch = appearance if solver.r > 0 else appearance.copy()
        solver.vote(matches, scratch, kind="mode")
        appearance = scratch = None  # type: ignore[assignment]  # freed before the dense map
        copy_source = solver.dense_source(matches, copied=True)
    solver.chosen = None
    if coarse_source is None:  # every level ends with its dense source map
        raise RuntimeError("no level was synthesized")
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
