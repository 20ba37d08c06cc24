"""Depth-map colorization as one explicit pipeline (Hassner & Basri 2006, and what we added).

:func:`colorize` runs :data:`STAGES` in order: each is a function
``(state, config) -> state`` with a name, a predicate saying whether the
configuration asks for it, and a line on what it changed (``imagemap synthesize
--verbose`` logs them; ``--report`` writes them). ``docs/design.md`` has a paragraph
per stage with its paper or reason.

=====================  ==================================================
stage                  what it does
=====================  ==================================================
``units``              the query at the examples' depth scale; not an example
``select``             the examples: named, or the nearest ``m`` in depth
``pyramid``            as many levels as the object's size calls for
``register``           each example warped onto the query (whole regions)
``bands``              guide bands of query and examples, their colour levels
``synthesize``         the engine, coarse to fine, by the level plan
``collapse``           the voted map at the finest level
``copy``               every pixel's source: the pixel its windows agree on
``complete_features``  small features the copy cut, copied whole
``seams``              a few whole copies, their seams where they agree
``outside``            the blend's reference outside the object: the copy
``blend``              the seams blended in the gradient domain
``rgb``                back to RGB, background 0
=====================  ==================================================

Examples
--------
>>> from imagemap import Database, Example
>>> yy, xx = np.mgrid[:40, :48]
>>> def blob(cy):
...     return np.where((yy - cy) ** 2 / 144 + (xx - 24) ** 2 / 324 < 1, 0.6, 0).astype(np.float32)
>>> def paint(depth):
...     return np.where((depth > 0)[..., None] & (yy[..., None] < 20), [0.8, 0.2, 0.1],
...                     np.where((depth > 0)[..., None], [0.9, 0.9, 0.6], 0.0))
>>> db = Database([Example.from_arrays(f"blob_{i}", blob(c), paint(blob(c)))
...                for i, c in enumerate((19, 20, 21))])
>>> result = colorize(blob(20), db.without("blob_1"), preset="fish", seed=0)
>>> result.image.shape, result.example_names
((40, 48, 3), ['blob_0', 'blob_2'])
>>> [stage.name for stage in result.stages][:3]
['units', 'select', 'pyramid']
"""

from __future__ import annotations

import logging
import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import Any

import numpy as np
from scipy import ndimage
from skimage import color

from imagemap.core.blend import copy_through
from imagemap.core.engine import EngineParams, EngineResult, ReleasableLevels, synthesize
from imagemap.core.poisson import seamless_copy
from imagemap.core.pyramid import collapse_laplacian
from imagemap.core.seams import place_seams
from imagemap.database import Database
from imagemap.depth import completion
from imagemap.depth.budget import guard_colorize
from imagemap.depth.config import OPTIONS, PRESETS, DepthConfig, resolve_config
from imagemap.depth.guides import (
    depth_mappings,
    example_mappings,
    example_ycbcr,
    level_plans,
    sized_pyramid,
    to_rgb,
)
from imagemap.depth.register import Warp, register, registered_positions
from imagemap.depth.selection import select_examples
from imagemap.depth.units import units_stage
from imagemap.example import Example
from imagemap.io import InputError, validate_depth
from imagemap.validate import check_examples, check_seed

__all__ = [
    "PRESETS",
    "STAGES",
    "ColorizeResult",
    "DepthConfig",
    "Stage",
    "StageRecord",
    "State",
    "colorize",
    "engine_params",
    "select_examples",
]

log = logging.getLogger("imagemap")


@dataclass
class State:
    """What the stages hand on to each other.

    The inputs (``depth``, ``database``, ``names``, ``seed``, ``quiet``) are set by
    :func:`colorize`; each stage fills in what it makes and drops what no later stage
    needs (the pyramids, the engine's levels), so that they do not add to the peak
    memory of the stages after it.
    """

    depth: np.ndarray
    database: Database
    seed: int = 0
    quiet: bool = True
    names: list[str] | None = None
    mask: np.ndarray = field(init=False)  # the object: depth > 0
    chosen: list[Example] = field(default_factory=list)
    warps: list[Warp] = field(default_factory=list)  # each example onto the query
    query_levels: ReleasableLevels | None = None
    exemplar_levels: list[ReleasableLevels] | None = None
    engine: EngineResult | None = None
    ycbcr: np.ndarray | None = None  # the voted map, then the map being finished (YCbCr)
    exemplars: list[np.ndarray] | None = None  # the examples' colours the copy reads
    source: np.ndarray | None = None  # (H, W, 3): example, y, x of every pixel
    features: list[tuple[np.ndarray, int]] | None = None  # the examples' small features
    image: np.ndarray | None = None
    changed: str = ""  # what the last stage changed, for the record

    def __post_init__(self) -> None:
        self.mask = np.asarray(self.depth) > 0

    def made(self, name: str) -> Any:
        """The value of ``name`` that an earlier stage made (an error naming it if none did:
        a stage run out of order)."""
        value = getattr(self, name)
        if value is None:
            raise RuntimeError(f"pipeline: no stage has made {name!r} yet (stage order)")
        return value


@dataclass(frozen=True)
class Stage:
    """A named step of the pipeline: ``run(state, config) -> state``, run when
    ``wanted(config)``."""

    name: str
    run: Callable[[State, DepthConfig], State]
    wanted: Callable[[DepthConfig], bool] = lambda config: True


@dataclass(frozen=True)
class StageRecord:
    """What a stage did in one run: its seconds and a line on what it changed
    ("off" when the configuration did not ask for it)."""

    name: str
    seconds: float
    changed: str


def _changed_pixels(old: np.ndarray, new: np.ndarray) -> int:
    """Pixels whose source differs between two source maps (by blocks of rows)."""
    if old is new:
        return 0
    count = 0
    for y in range(0, old.shape[0], 256):
        count += int(np.count_nonzero((old[y : y + 256] != new[y : y + 256]).any(axis=-1)))
    return count


# -- the stages ------------------------------------------------------------------------


def _select(state: State, config: DepthConfig) -> State:
    database = state.database
    if state.names:
        state.chosen = [database[name] for name in state.names]
    else:
        n = config.selection.m
        if n > len(database):
            log.warning("m=%d but the database has %d examples: using all", n, len(database))
            n = len(database)
        state.chosen = [database[i] for i in select_examples(state.depth, database, n)]
    state.changed = ", ".join(e.name for e in state.chosen)
    return state


def _pyramid(state: State, config: DepthConfig) -> State:
    state.changed = f"{config.pyramid.levels} levels: windows {config.pyramid.patch_sizes}"
    return state


def _register(state: State, config: DepthConfig) -> State:
    state.warps = [
        register(state.depth, example.depth, registration=config.registration)
        for example in state.chosen
    ]
    state.changed = f"{len(state.warps)} examples warped onto the query"
    return state


def _bands(state: State, config: DepthConfig) -> State:
    levels = config.pyramid.levels
    query_positions: list[np.ndarray] | None = None
    example_positions: list[list[np.ndarray] | None] = [None] * len(state.chosen)
    if state.warps:
        query_positions, registered = registered_positions(
            state.mask,
            [e.depth.shape for e in state.chosen],
            state.warps,
            levels,
            grid_points=config.registration.position_grid,
        )
        example_positions = list(registered)
    # Handed over to the engine, which drops each level once it has packed its bands.
    state.query_levels = ReleasableLevels(
        depth_mappings(state.depth, levels, config.guides, query_positions)
    )
    state.exemplar_levels = [
        ReleasableLevels(
            example_mappings(
                e, levels, config.matching.appearance_pyramid, config.guides, positions
            )
        )
        for e, positions in zip(state.chosen, example_positions, strict=True)
    ]
    state.changed = f"{len(state.chosen)} examples"
    return state


def engine_params(config: DepthConfig, mask: np.ndarray, n_examples: int) -> EngineParams:
    """The engine's parameters for ``config`` (sized for the object) and ``n_examples``.

    Examples
    --------
    >>> mask = np.zeros((150, 200), bool); mask[30:120, 50:150] = True
    >>> params = engine_params(DepthConfig(), mask, 2)
    >>> params.guide_weights, [plan.patch_size for plan in params.levels]
    ((1.0, 2.0, 0.5), [7, 11, 9])
    """
    guides, matching = config.guides, config.matching
    return EngineParams(
        patch_sizes=config.pyramid.patch_sizes,
        guide_weights=(guides.depth_weight, guides.depth_detail_weight)
        + ((guides.silhouette_weight,) if guides.silhouette_weight else ()),
        appearance_weights=(matching.luma_weight, matching.chroma_weight, matching.chroma_weight),
        position_weight=(
            guides.registered_position_weight if guides.registration else guides.position_weight
        ),
        pca_fraction=matching.pca_fraction,
        backend=matching.backend,
        max_iterations=matching.max_iterations,
        tolerance=matching.tolerance,
        guide_padding="constant",
        vote="mode" if config.finish.vote == "mode" else "mean",
        levels=level_plans(config, mask, n_examples),
        appearance_pyramid=matching.appearance_pyramid,
    )


def _synthesize(state: State, config: DepthConfig) -> State:
    params = engine_params(config, state.mask, len(state.chosen))
    query, exemplars = state.made("query_levels"), state.made("exemplar_levels")
    # The pyramids are the engine's now (it frees each level once packed): not held here.
    state.query_levels = state.exemplar_levels = None
    engine = synthesize(query, exemplars, params, seed=state.seed, quiet=state.quiet)
    del query, exemplars
    state.engine = engine
    state.changed = "iterations per level (fine to coarse): " + ", ".join(
        str(len(values)) for values in engine.objective
    )
    return state


def _collapse(state: State, config: DepthConfig) -> State:
    engine: EngineResult = state.made("engine")
    if config.matching.appearance_pyramid == "laplacian":
        state.ycbcr = collapse_laplacian(engine.appearance)
    else:
        state.ycbcr = engine.appearance[0]
    engine.appearance = None  # type: ignore[assignment]  # collapsed: not held through the finish
    if not config.finish.copies:
        state.source = engine.source
        engine.source = engine.copy_source = None  # type: ignore[assignment]  # handed over
    state.changed = "voted map"
    return state


def _copy(state: State, config: DepthConfig) -> State:
    # Every pixel copied from the exemplar pixel its windows agree on. The examples'
    # colours are made again rather than kept from the pyramids: full-size arrays held
    # through the synthesis would add to its peak memory, and they cost little to remake.
    engine: EngineResult = state.made("engine")
    state.exemplars = [example_ycbcr(example) for example in state.chosen]
    copied = state.source = engine.copy_source
    differ = 0 if copied is None else _changed_pixels(engine.source, copied)
    engine.source = engine.copy_source = None  # type: ignore[assignment]  # handed over
    state.changed = f"{differ} pixels copied from another source than their window's match"
    return state


def _seams(state: State, config: DepthConfig) -> State:
    old = state.made("source")
    exemplars = state.made("exemplars")
    # A small feature (an eye, a brow) that the map copies from an example's, completed
    # whole by the stage before, or that the voted map shows, only takes labels it already
    # uses: the rearrangement weighs colours against seams, and a small feature's outline
    # is long for its few pixels of colour (a low-contrast eye ring lost to its seams). It
    # may still become one of its own copies: an eye copied in pieces from two examples.
    shown, _ = completion.small_features(
        state.made("ycbcr"), state.mask, completion=config.completion
    )
    kept = completion.copies_features(old, _features(state, config)) | (shown > 0)
    del shown
    size = float(np.sqrt(state.mask.sum()))
    new = place_seams(
        exemplars,
        old,
        state.made("ycbcr"),
        smoothness=config.finish.seam_smoothness * size / 100.0,
        spread=config.finish.seam_spread,
        mask=state.mask,
        exemplar_masks=[example.mask for example in state.chosen],
        groups=ndimage.label(kept & state.mask)[0],
    )
    state.source = new
    state.changed = f"{_changed_pixels(old, new)} pixels take another source"
    return state


def _features(state: State, config: DepthConfig) -> list[tuple[np.ndarray, int]]:
    """The chosen examples' small features (:func:`completion.small_features`)."""
    if state.features is None:
        state.features = [
            completion.small_features(exemplar, example.mask, completion=config.completion)
            for exemplar, example in zip(state.made("exemplars"), state.chosen, strict=True)
        ]
    return state.features


def _complete_features(state: State, config: DepthConfig) -> State:
    exemplars = state.made("exemplars")
    state.source, completed = completion.complete_features(
        exemplars,
        state.made("source"),
        _features(state, config),
        state.mask,
        [example.mask for example in state.chosen],
        relief=(state.depth, [example.depth for example in state.chosen]),
        completion=config.completion,
    )
    log.info("small features completed: %d", completed)
    state.changed = f"{completed} small features copied whole"
    return state


_ROWS = 256  # rows per block where the finish works row by row (no full-size float64 copy)


def _outside(state: State, config: DepthConfig) -> State:
    # Outside the object the voted map is whatever the windows left there (zero where no
    # window reached: black in YCbCr terms is green); the blend must not pull the
    # object's edge towards it, so the reference there is the copy itself.
    mask, source, ycbcr = state.mask, state.made("source"), state.made("ycbcr")
    exemplars = state.made("exemplars")
    state.features = None  # label maps: not held through the blend, the finish's peak
    count = 0
    for y0 in range(0, mask.shape[0], _ROWS):
        rows = slice(y0, y0 + _ROWS)
        outside = ~mask[rows] & (source[rows, :, 0] >= 0)
        if outside.any():
            ycbcr[rows][outside] = copy_through(exemplars, source[rows][outside][None])[0]
            count += int(outside.sum())
    state.changed = f"{count} pixels outside the object set to the copy"
    return state


def _blend(state: State, config: DepthConfig) -> State:
    size = float(np.sqrt(state.mask.sum()))
    scale = max(config.finish.blend_scale * size, 1.0)
    state.ycbcr = seamless_copy(
        state.made("exemplars"),
        state.made("source"),
        state.made("ycbcr"),
        scale=scale,
        edge_support=config.finish.edge_support,
        edge_contrast=config.finish.edge_contrast,
        edge_floor=config.finish.edge_floor,
        mask=state.mask,
    )
    state.exemplars = None
    state.changed = f"seams blended at scale {scale:.1f} px"
    return state


def _rgb(state: State, config: DepthConfig) -> State:
    image = to_rgb(state.made("ycbcr"))
    image[~state.mask] = 0.0
    state.image, state.ycbcr = image, None
    state.changed = "RGB"
    return state


def _copies(config: DepthConfig) -> bool:
    return config.finish.copies


#: The pipeline, in order.
STAGES: tuple[Stage, ...] = (
    Stage("units", units_stage),  # imagemap/depth/units.py: depth scale, the query itself
    Stage("select", _select),
    Stage("pyramid", _pyramid),
    Stage("register", _register, lambda c: c.guides.registration),
    Stage("bands", _bands),
    Stage("synthesize", _synthesize),
    Stage("collapse", _collapse),
    Stage("copy", _copy, _copies),
    Stage(
        "complete_features",
        _complete_features,
        lambda c: c.finish.copies and c.finish.complete_features,
    ),
    Stage("seams", _seams, lambda c: c.finish.copies and c.finish.seam_smoothness > 0),
    Stage("outside", _outside, _copies),
    Stage("blend", _blend, _copies),
    Stage("rgb", _rgb),
)

#: Stages whose seconds are reported as ``timings["selection"]``, ``["pyramids"]``; the
#: engine reports its own; every stage after it counts as ``timings["collapse"]``.
_TIMING_GROUPS = {
    "select": "selection",
    "pyramid": "pyramids",
    "register": "pyramids",
    "bands": "pyramids",
}


def run_pipeline(
    state: State, config: DepthConfig, stages: tuple[Stage, ...] = STAGES
) -> tuple[State, DepthConfig, list[StageRecord]]:
    """Run ``stages`` on ``state``; returns the final state, the configuration as run
    (the ``pyramid`` stage sizes it for the object) and a record per stage."""
    records = []
    for stage in stages:
        if not stage.wanted(config):
            records.append(StageRecord(stage.name, 0.0, "off"))
            continue
        start = time.perf_counter()
        if stage.name == "pyramid":  # the configuration itself is sized here
            config = replace(config, pyramid=sized_pyramid(state.mask, config.pyramid))
        state.changed = ""
        state = stage.run(state, config)
        seconds = time.perf_counter() - start
        records.append(StageRecord(stage.name, seconds, state.changed))
        log.info("stage %s: %.3f s; %s", stage.name, seconds, state.changed)
    state.changed = ""
    return state, config, records


_PALETTE = np.array(
    [
        [0.90, 0.10, 0.10],
        [0.10, 0.45, 0.95],
        [0.10, 0.75, 0.20],
        [0.95, 0.70, 0.05],
        [0.65, 0.20, 0.85],
        [0.05, 0.80, 0.80],
        [0.95, 0.40, 0.70],
        [0.50, 0.50, 0.50],
    ],
    dtype=np.float32,
)


@dataclass
class ColorizeResult:
    """A synthesised image-map and how it was made.

    Attributes
    ----------
    image : ndarray, (H, W, 3) float32 in [0, 1]
        The image-map (background pixels are 0; see :attr:`rgba`).
    mask : ndarray of bool, (H, W)
        The object (non-background depth).
    source : ndarray of int32, (H, W, 3)
        Per pixel: index into :attr:`example_names`, source y, source x.
    cost : ndarray of float32, (H, W)
        Match cost of the window centred at each pixel (finest level).
    example_names : list of str
        The examples used, in the order of the indices of :attr:`source`.
    objective : list of list of float
        Target value per EM iteration, per level (finest first).
    timings : dict
        Seconds: ``selection``, ``pyramids``, the engine's own steps, ``collapse``
        (every stage after the engine).
    config : DepthConfig
        The configuration that ran (its pyramid sized for the object).
    stages : list of StageRecord
        Per stage of :data:`STAGES`: seconds and what it changed.
    """

    image: np.ndarray
    mask: np.ndarray
    source: np.ndarray
    cost: np.ndarray
    example_names: list[str]
    objective: list[list[float]]
    timings: dict[str, float] = field(default_factory=dict)
    config: DepthConfig | None = None
    stages: list[StageRecord] = field(default_factory=list)

    @property
    def rgba(self) -> np.ndarray:
        """(H, W, 4) image with a transparent background."""
        return np.concatenate([self.image, self.mask[..., None].astype(np.float32)], axis=2)

    def on_background(self, colour: tuple[float, float, float]) -> np.ndarray:
        """(H, W, 3) image with the background set to ``colour`` (RGB in [0, 1])."""
        out = self.image.copy()
        out[~self.mask] = np.asarray(colour, dtype=np.float32)
        return out

    @cached_property
    def provenance(self) -> np.ndarray:
        """A picture of which example each region came from (Fig. 2c of the paper).

        The image-map's luminance tinted with one colour per example, with the
        borders between regions from different examples drawn dark.
        """
        index = self.source[..., 0]
        tint = _PALETTE[index % len(_PALETTE)]
        luma = color.rgb2gray(self.image)[..., None]
        picture = 0.45 * tint + 0.55 * luma * (0.5 + tint)
        border = ndimage.morphological_gradient(index, size=3) > 0
        picture[border & self.mask] = 0.05
        picture[~self.mask] = 1.0
        return np.clip(picture, 0, 1).astype(np.float32)

    @property
    def legend(self) -> list[tuple[str, tuple[float, float, float]]]:
        """(example name, tint colour) for the provenance picture."""
        tints = [_PALETTE[i % len(_PALETTE)] for i in range(len(self.example_names))]
        return [
            (name, (float(tint[0]), float(tint[1]), float(tint[2])))
            for name, tint in zip(self.example_names, tints, strict=True)
        ]


def _check_arguments(depth, database, preset, examples, seed) -> list[str] | None:
    """The arguments :func:`colorize` checks before any work; ``examples`` as a list."""

    if isinstance(depth, (str, os.PathLike)):
        raise InputError(
            f"depth: expected an array, got the path {os.fspath(depth)!r} "
            "(read it with imagemap.read_depth)"
        )
    if not isinstance(database, Database):
        raise InputError(
            "database: expected an imagemap.Database (Database.from_directory(DIR), or "
            f"Database([Example.from_arrays(...), ...])), got {type(database).__name__}"
        )
    if preset is not None and not isinstance(preset, (str, DepthConfig)):
        raise InputError(f"preset: expected a preset name or DepthConfig, got {preset!r}")
    names = check_examples(examples)
    check_seed(seed)
    for name in names or ():
        database[name]  # an unknown name is an InputError listing the known ones
    return names


def colorize(
    depth: np.ndarray,
    database: Database,
    preset: str | DepthConfig | None = "busts",
    *,
    examples: list[str] | None = None,
    seed: int = 0,
    quiet: bool = True,
    **options: Any,
) -> ColorizeResult:
    """Synthesise an image-map for ``depth`` from the examples of ``database``.

    Parameters
    ----------
    depth : ndarray, (H, W)
        Query depth; larger is nearer, 0 or NaN is background.
    database : Database
        Examples of the same class.
    preset : str or DepthConfig
        ``"humans"``, ``"busts"``, ``"fish"`` (:data:`imagemap.depth.config.PRESETS`)
        or an explicit configuration.
    examples : list of str, optional
        Use these examples by name instead of the automatic selection.
    seed : int
        The same seed gives the same bytes.
    quiet : bool
        No progress bar.
    **options
        Any of :data:`imagemap.depth.config.OPTIONS`, overriding the preset (None:
        the preset's): {options}.

    Returns
    -------
    ColorizeResult

    Raises
    ------
    InputError
        A bad argument or option (named), or a run too large for the memory available
        (:func:`imagemap.depth.budget.guard_colorize`), before any work.

    Examples
    --------
    See the module's example.
    """
    names = _check_arguments(depth, database, preset, examples, seed)
    config = resolve_config(preset, **options)
    guard_colorize(depth, database, config, examples=names)
    depth = validate_depth(depth)
    if len(database) == 0:
        raise InputError("the database has no examples")
    state = State(depth=depth, database=database, seed=seed, quiet=quiet, names=names)
    state, config, records = run_pipeline(state, config)
    engine: EngineResult = state.made("engine")
    timings: dict[str, float] = {"selection": 0.0, "pyramids": 0.0}
    timings.update(engine.timings)
    timings["collapse"] = 0.0
    seen_engine = False
    for record in records:
        if record.name == "synthesize":
            seen_engine = True
        elif record.name in _TIMING_GROUPS:
            timings[_TIMING_GROUPS[record.name]] += record.seconds
        elif seen_engine:
            timings["collapse"] += record.seconds
    return ColorizeResult(
        image=state.made("image"),
        mask=state.mask,
        source=state.made("source"),
        cost=engine.cost,
        example_names=[e.name for e in state.chosen],
        objective=engine.objective,
        timings=timings,
        config=config,
        stages=records,
    )


colorize.__doc__ = (colorize.__doc__ or "").replace(
    "{options}", ", ".join(f"``{option.name}``" for option in OPTIONS)
)
