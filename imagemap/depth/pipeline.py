"""Depth-map colorization as one explicit pipeline (Hassner & Basri 2006, and what we added).

One module for one job: the depth front end's stages, its result and its entry points.

:func:`colorize` sizes the pyramid for the object (as many levels as its size calls
for), then runs :data:`STAGES` in order with :func:`imagemap.core.stages.run_pipeline`:
each is a function ``(state, config) -> state`` with a name, a predicate saying whether
the configuration asks for it, and a line on what it changed (``imagemap synthesize
--verbose`` logs them; ``--report`` writes them). The stages from ``collapse`` on are
the finish every colour synthesis shares (:mod:`imagemap.depth.finish`).
``docs/design.md`` has a paragraph per stage with its paper or reason.

=====================  ==================================================
stage                  what it does
=====================  ==================================================
``units``              the query at the examples' depth scale; not an example
``select``             the examples: named, or the nearest ``m`` in depth
``working``            a large query and its examples block-averaged to
                       the search size (``pyramid.search_size``)
``register``           each example warped onto the query (whole regions)
``bands``              guide bands of query and examples, their colour levels
``synthesize``         the engine, coarse to fine, by the level plan
``collapse``           the voted map at the finest level
``copy``               every pixel's source: the pixel its windows agree on
``complete_features``  small features the copy cut, copied whole
``relief``             the relief's detail and the seams' weights, for the seams
``seams``              a few whole copies, their seams where they agree
``fine``               a large query's sources and map at full size
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
['select', 'pose', 'working']
"""

from __future__ import annotations

import logging
import os
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import Any

import numpy as np
from scipy import ndimage

from imagemap.core.blend import copy_through, nearest_object_pixels
from imagemap.core.engine import EngineParams, ReleasableLevels, synthesize
from imagemap.core.finecopy import fine_positions
from imagemap.core.stages import Stage, StageRecord, run_pipeline
from imagemap.database import Database
from imagemap.depth import completion
from imagemap.depth.budget import averaging_factor, guard_colorize
from imagemap.depth.config import OPTIONS, PRESETS, DepthConfig, resolve_config
from imagemap.depth.finish import (
    BLEND,
    COLLAPSE,
    COPY,
    OUTSIDE,
    RGB,
    SEAMS,
    SynthesisState,
    example_features,
)
from imagemap.depth.guides import (
    depth_mappings,
    example_colours,
    example_mappings,
    example_ycbcr,
    level_plans,
    sized_config,
)
from imagemap.depth.pose import (
    CanonicalFrame,
    Pose,
    PosedExample,
    absorbed_pose,
    canonical_frame,
    resample_depth,
    unpose,
    unpose_nearest,
)
from imagemap.depth.register import (
    Warp,
    block_average,
    example_positions,
    position_frame,
    position_scales,
    query_positions,
    register_with_detail,
    relief_agreement,
    relief_detail,
)
from imagemap.depth.schedule import each_example
from imagemap.depth.selection import poses_against, select_examples, select_with_poses
from imagemap.depth.units import exclude_query, units_free
from imagemap.io import InputError, validate_depth
from imagemap.validate import check_examples, check_seed

__all__ = [
    "PRESETS",
    "STAGES",
    "WARP_NEAREST_STAGES",
    "ColorizeResult",
    "DepthConfig",
    "State",
    "colorize",
    "engine_params",
    "select_examples",
    "warp_nearest",
]

log = logging.getLogger("imagemap")


@dataclass(kw_only=True)
class State(SynthesisState):
    """What the depth front end's stages hand on to each other.

    The inputs (``depth``, ``database``, ``names``, ``seed``, ``quiet``) are set by
    :func:`colorize`; the mask is the depth's object. The finish's fields are
    :class:`~imagemap.depth.finish.SynthesisState`'s.
    """

    depth: np.ndarray  # the query's depth; from the pose stage on, in the canonical frame
    database: Database
    names: list[str] | None = None
    mask: np.ndarray = field(init=False)  # the object: depth > 0
    query_depth: np.ndarray = field(init=False)  # the query's depth as given
    poses: list[Pose] = field(default_factory=list)  # the query against each example
    frame: CanonicalFrame | None = None  # where the synthesis runs
    mirrored: list[bool] = field(default_factory=list)  # chosen[i] is the example mirrored
    angles: list[float] = field(default_factory=list)  # each example's turn from the frame
    warps: list[Warp] = field(default_factory=list)  # each example onto the query
    # Above the search size: the block-averaging factor, and the full-size depth, mask and
    # examples while the synthesis and the seams run on the averaged ones.
    factor: int = 1
    full: tuple[np.ndarray, np.ndarray, list[Any]] | None = None
    searched: np.ndarray | None = None  # the object the engine searched, when averaged
    finest_scale: np.ndarray | None = None  # the finest level's position factor (bands)
    # The query's then each example's nearest object pixels where the registration made
    # them from its full-size mask (Registered.nearest), for the bands, which drop them.
    nearest: list[np.ndarray | None] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.query_depth = self.depth
        self.mask = np.asarray(self.depth) > 0


# -- the stages ------------------------------------------------------------------------


def _select(state: State, config: DepthConfig) -> State:
    # The query itself is no example of its own; then the nearest in shape, at any pose.
    state.database, note = exclude_query(state.database, state.names, state.depth)
    database, selection = state.database, config.selection
    if state.names:
        chosen = [database[name] for name in state.names]
        state.poses = poses_against(state.depth, chosen, selection)
    else:
        n = selection.m
        if n > len(database):
            log.warning("m=%d but the database has %d examples: using all", n, len(database))
            n = len(database)
        indices, state.poses = select_with_poses(state.depth, database, n, selection)
        chosen = [database[i] for i in indices]
    state.chosen = chosen
    state.changed = "; ".join(filter(None, [note, ", ".join(e.name for e in chosen)]))
    return state


def _relative_angle(pose: Pose, first: Pose, mirrored: bool) -> float:
    """The turn (degrees) from the canonical frame (``first``'s example) to ``pose``'s
    example, that example mirrored when ``mirrored``."""
    matrix = pose.linear @ np.linalg.inv(first.linear)
    if mirrored:
        matrix = np.diag([1.0, -1.0]) @ matrix
    return float(np.degrees(np.arctan2(matrix[1, 0], matrix[0, 0])))


def _pose(state: State, config: DepthConfig) -> State:
    # The synthesis runs in the first example's frame: the query turned, scaled and
    # mirrored as that example lies, at its depth scale; an example that lies mirrored
    # against it is used mirrored (exactly: its columns reversed). A turn and a scale the
    # registration's warp absorbs are left to it: the query is then only moved (and
    # mirrored), by whole pixels, not resampled.
    first = absorbed_pose(state.poses[0], config.selection)
    size = float(np.sqrt(state.chosen[0].mask.sum()))
    # Room around the object for the coarsest level's windows (about a third of the
    # object wide: Pyramid.add_windows_across) and the depth continued past the outline.
    margin = size / (2.0 * config.pyramid.add_windows_across) + 2 * config.guides.extension_sigma
    levels = sized_config(config, state.chosen[0].mask).pyramid.levels
    frame = canonical_frame(state.mask, first, margin, align=2 ** (levels - 1))
    # Depth units never count: the query and every example divided by their own median
    # depth (units_free), the same values whatever the unit.
    state.depth = resample_depth(units_free(state.query_depth), frame)
    state.mask = state.depth > 0
    state.frame = frame
    state.mirrored = [pose.mirrored != first.mirrored for pose in state.poses]
    state.angles = [
        _relative_angle(pose, first, flip)
        for pose, flip in zip(state.poses, state.mirrored, strict=True)
    ]
    state.chosen = [
        PosedExample.of(e, mirrored=flip)
        for e, flip in zip(state.chosen, state.mirrored, strict=True)
    ]
    if not getattr(state.database, "keep_arrays", True):
        # Memory: from here on the synthesis reads the posed copies; the depths the
        # selection read (every example's) are not held through it.
        state.database.release_arrays()
    found = state.poses[0]
    state.changed = (
        f"turned {found.angle:.1f} deg, scaled x{found.scale:.3f}"
        f"{', mirrored' if found.mirrored else ''}"
        f"{' (left to the warp)' if first.scale == 1.0 and first.angle == 0.0 else ''}; "
        f"{sum(state.mirrored)} examples used mirrored"
    )
    return state


@dataclass
class WorkingExample:
    """A posed example block-averaged to the search size
    (:func:`~imagemap.depth.register.block_average`): what
    the synthesis reads of an example (name, depth, mask, image)."""

    name: str
    depth: np.ndarray
    image: np.ndarray
    mirrored: bool = False  # already arranged as its posed example was
    labels: np.ndarray | None = None

    @property
    def mask(self) -> np.ndarray:
        return self.depth > 0


def _block_means(image: np.ndarray, factor: int) -> np.ndarray:
    """An image's means over ``factor`` x ``factor`` blocks in float32 (the last blocks
    padded with their edge: an example's picture continues past its frame)."""
    height, width = image.shape[:2]
    h, w = -(-height // factor), -(-width // factor)
    widths = [(0, h * factor - height), (0, w * factor - width)] + [(0, 0)] * (image.ndim - 2)
    padded = np.pad(np.asarray(image, dtype=np.float32), widths, mode="edge")
    blocks = padded.reshape(h, factor, w, factor, *image.shape[2:])
    return blocks.sum(axis=(1, 3), dtype=np.float32) / np.float32(factor * factor)


def _working(state: State, config: DepthConfig) -> State:
    # A query larger than the search size: the synthesis, the copy and the seams run on
    # it and its (posed) examples block-averaged by a power of two; the fine stage
    # brings the sources back to full size. The frame's origin is on a multiple of the
    # pyramid's coarsest step (the pose stage), so the averaged examples' blocks and the
    # averaged query's share their corners.
    levels = sized_config(config, state.chosen[0].mask).pyramid.levels
    size = float(np.sqrt(state.mask.sum()))
    factor = averaging_factor(size, config.pyramid.search_size, 2 ** (levels - 1))
    if factor == 1:
        state.changed = "none: the object is within the search size"
        return state
    state.full = (state.depth, state.mask, state.chosen)
    state.factor = factor
    state.depth = block_average(state.depth, state.mask, factor, pad=True)[0]
    state.mask = state.searched = state.depth > 0
    state.chosen = [
        WorkingExample(
            name=e.name,
            depth=block_average(e.depth, e.mask, factor, pad=True)[0],
            image=_block_means(e.image, factor),
        )
        for e in state.chosen
    ]
    state.changed = (
        f"averaged by {factor}: {state.mask.shape[1]}x{state.mask.shape[0]}, object "
        f"{np.sqrt(state.mask.sum()):.0f} px across"
    )
    return state


def fine_source(source: np.ndarray, factor: int, shape: tuple[int, int],
                example_shapes: list[tuple[int, int]]) -> np.ndarray:  # fmt: skip
    """A source map of block-averaged pictures at full size: pixel ``(y, x)`` copies the
    full-size pixel nearest to its position in its block's copy
    (:func:`imagemap.core.finecopy.fine_positions`: interpolated between the blocks'
    centres where the neighbouring blocks continue the copy); clipped to its example, -1
    kept where there is no source.

    Within a block whose neighbours continue a translated copy, pixel ``(y, x)`` copies
    ``(e, factor * sy + y % factor, factor * sx + x % factor)``, ``(e, sy, sx)`` the
    block's source: the same place in the source's block. A copy that drifts by one
    averaged pixel steps by one full-size pixel at a time, as a full-size synthesis's
    slowly warping copy does, instead of jumping ``factor`` pixels at a block's edge.
    Seams (another example, a larger jump) are kept where the blocks put them.

    Examples
    --------
    >>> source = np.array([[[0, 3, 5], [1, 0, 0]]], np.int32)
    >>> fine = fine_source(source, 2, (2, 3), [(8, 12), (8, 12)])
    >>> fine[..., 1].tolist(), fine[..., 2].tolist()
    ([[6, 6, 0], [7, 7, 1]], [[10, 11, 0], [10, 11, 0]])

    A copy drifting by one averaged pixel between two blocks steps by one pixel:

    >>> drift = np.array([[[0, 0, 4], [0, 0, 6]]], np.int32)  # offsets 4 and 5
    >>> fine = fine_source(drift, 2, (2, 4), [(8, 16)])
    >>> (fine[0, :, 2] - np.arange(4)).tolist()  # by blocks alone: 8, 8, 10, 10
    [8, 9, 10, 10]
    """
    height, width = shape
    heights = np.array([s[0] for s in example_shapes], dtype=np.int64)
    widths = np.array([s[1] for s in example_shapes], dtype=np.int64)
    fine = np.empty((height, width, 3), dtype=np.int32)
    for y0 in range(0, height, _ROWS):
        y1 = min(y0 + _ROWS, height)
        index, sy, sx = fine_positions(source, factor, shape, (y0, y1))
        known = np.clip(index, 0, len(example_shapes) - 1)
        # The full-size pixel whose centre is nearest: (p + 0.5) * factor - 0.5, rounded.
        fine[y0:y1, :, 0] = index
        fine[y0:y1, :, 1] = np.clip(np.floor((sy + 0.5) * factor), 0, heights[known] - 1)
        fine[y0:y1, :, 2] = np.clip(np.floor((sx + 0.5) * factor), 0, widths[known] - 1)
    return fine


_ROWS = 256  # rows per block where a full-size map is made block by block


@dataclass(frozen=True)
class ExampleFrame:
    """A chosen example once the fine stage has made its colours at full size: its name
    and its frame's (height, width), what the stages after it read of it. Its posed
    full-size depth (4 bytes a pixel) is not held through the blend, the peak of a map
    synthesized averaged."""

    name: str
    shape: tuple[int, int]


def _fine(state: State, config: DepthConfig) -> State:
    # The sources at full size (each pixel from the same place in its source's block of
    # the full-size example: the examples' own detail), the map being finished (the
    # blend's reference) upsampled; the blend then runs at full size.
    if state.full is None:
        state.changed = "none: the synthesis ran at full size"
        return state
    factor = state.factor
    small_mask = state.mask
    state.depth, state.mask, state.chosen = state.full
    state.full = None
    shape = state.mask.shape
    source = state.made("source")
    # A full-size object pixel whose block is not object (its outline) may have no
    # source: the nearest block's that has one.
    missing = source[..., 0] < 0
    if missing.any():
        reach = ndimage.binary_dilation(small_mask, iterations=2) & missing
        iy, ix = ndimage.distance_transform_edt(
            missing, return_distances=False, return_indices=True
        )
        source[reach] = source[iy[reach], ix[reach]]
    state.source = fine_source(source, factor, shape, [e.shape for e in state.chosen])
    del source
    ycbcr = state.made("ycbcr")
    state.ycbcr = np.ascontiguousarray(
        ndimage.zoom(ycbcr, (factor, factor, 1), order=1, mode="nearest", grid_mode=True)[
            : shape[0], : shape[1]
        ],
        dtype=np.float32,
    )
    del ycbcr
    if state.exemplars is not None:
        state.exemplars = [example_ycbcr(example) for example in state.chosen]
    # Memory: from here on the examples' names and sizes are read, not their depths.
    state.chosen = [ExampleFrame(e.name, e.shape) for e in state.chosen]
    state.features = None
    if state.engine is not None:
        cost = state.engine.cost
        state.engine.cost = np.repeat(np.repeat(cost, factor, 0), factor, 1)[: shape[0], : shape[1]]
    state.changed = f"sources and map at full size ({shape[1]}x{shape[0]}, x{factor})"
    return state


def _register(state: State, config: DepthConfig) -> State:
    registered = register_with_detail(
        state.depth,
        [example.depth for example in state.chosen],
        registration=config.registration,
        angles=state.angles,
        keep_nearest=max(e.depth.size for e in [state, *state.chosen]) <= KEEP_NEAREST_PIXELS,
    )
    state.warps = registered.warps
    state.nearest = registered.nearest
    if _relief_channel(config):
        # The relief's detail the residuals were made from is the seams' relief channel
        # where it is at full size (objects up to 1.5 detail_size across: 12 bytes a
        # pixel with two examples held through the synthesis, a few MB at most): the
        # relief stage does not make it again (0.07-0.09 s at 512^2).
        state.relief = registered.detail
    state.changed = f"{len(state.warps)} examples warped onto the query"
    return state


#: Frames up to this many pixels (1024 x 1024) keep the nearest object pixels the
#: registration made (Registered.nearest) for the bands' fills and depth continuation, one
#: feature transform less per map (34 ms for the three at 512^2): 8 bytes a pixel per map,
#: held from the registration to the end of the bands (6 MB at 512^2, 24 MB at 1024^2).
#: Larger frames' bands make them again, one example at a time.
KEEP_NEAREST_PIXELS = 2**20


def _relief_channel(config: DepthConfig) -> bool:
    """Whether the seams read the relief's detail (the relief stage makes it)."""
    return SEAMS.wanted(config) and config.finish.seam_relief_weight > 0


def _bands(state: State, config: DepthConfig) -> State:
    levels = sized_config(config, state.mask).pyramid.levels
    frame = position_frame(state.mask) if state.warps else None
    # The examples cut to their objects and the margin the engine's windows read (an
    # object is often a third of its frame): the same synthesis, the frames not held.
    params = engine_params(sized_config(config, state.mask), state.mask, len(state.chosen))
    radius = max(plan.patch_size for plan in params.level_plans(levels)) // 2
    keep = config.finish.copies and all(e.depth.size <= KEEP_COLOURS_PIXELS for e in state.chosen)
    # Each example's levels and kept colours by its index (filled on the threads).
    exemplar_levels: dict[int, ReleasableLevels] = {}
    nearest: list[np.ndarray | None] = state.nearest or [None] * (1 + len(state.chosen))
    state.nearest = []
    kept: dict[int, np.ndarray] = {}

    # The query's bands in two tasks, its guides and its positions with their factors,
    # each about half an example's: on two threads the four tasks end about together.
    query: dict[str, Any] = {}

    def query_guides() -> None:
        query["guides"] = depth_mappings(state.depth, levels, config.guides, None, None, nearest[0])
        nearest[0] = None

    def query_factors() -> None:
        query["positions"] = (
            None if frame is None else query_positions(state.mask.shape, frame, levels)
        )
        query["scales"] = _position_factors(state, config, levels)

    def example_bands(index: int) -> None:
        e = state.chosen[index]
        positions = None
        if frame is not None:
            positions = example_positions(
                e.depth.shape,
                state.warps[index],
                frame,
                levels,
                grid_points=int(config.registration.detail_size),
            )
        colours = example_colours(e, nearest[1 + index])
        nearest[1 + index] = None  # read: not held to the stage's end
        if keep:
            kept[index] = colours[0]
        exemplar_levels[index] = ReleasableLevels(
            example_mappings(
                e,
                levels,
                config.matching.appearance_pyramid,
                config.guides,
                positions,
                crop_radius=radius,
                colours=colours,
            )
        )

    # The query's bands and each example's on the kernels' threads (SciPy's filters,
    # distance transforms and interpolation release the GIL): each its own arrays, the
    # same bytes, in example order.
    tasks = [query_guides, query_factors]
    each_example(
        lambda task: tasks[task]() if task < len(tasks) else example_bands(task - len(tasks)),
        [state.depth.shape, state.depth.shape, *(e.depth.shape for e in state.chosen)],
    )
    scales = query["scales"]
    # The finest level's factor is the seams' weights' too (the relief stage): kept, not
    # made again (the engine holds it until it has packed the finest level anyway).
    state.finest_scale = None if scales is None else scales[0]
    # Handed over to the engine, which drops each level once it has packed its bands.
    state.query_levels = ReleasableLevels(
        [
            replace(level, position=position, position_scale=scale)
            for level, position, scale in zip(
                query.pop("guides"),
                query.pop("positions") or [None] * levels,
                scales or [None] * levels,
                strict=True,
            )
        ]
    )
    order = range(len(state.chosen))
    state.exemplar_levels = [exemplar_levels[index] for index in order]
    state.colours = [kept[index] for index in order] if keep else None
    state.changed = f"{len(state.chosen)} examples"
    return state


#: Examples' frames up to this many pixels (724 x 724) keep the colours the bands made
#: (12 bytes a pixel each, held through the synthesis: 6 MB for two at 512^2) for the copy
#: stage, which otherwise reads each picture again, fills its background (a distance
#: transform) and converts it (about 20 ms an example at 512^2). Larger frames make them
#: again: two 1024^2 examples' 25 MB would add to the synthesis' peak.
KEEP_COLOURS_PIXELS = 2**19


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
        levels=level_plans(config, mask, n_examples),
        guide_weights=(guides.depth_weight, guides.depth_detail_weight)
        + ((guides.silhouette_weight,) if guides.silhouette_weight else ()),
        appearance_weights=(matching.luma_weight, matching.chroma_weight, matching.chroma_weight),
        position_weight=(
            guides.registered_position_weight if guides.registration else guides.position_weight
        ),
        pca_fraction=matching.pca_fraction,
        backend=matching.backend,
        tolerance=matching.tolerance,
        guide_padding="constant",
        vote=config.finish.vote,
        appearance_pyramid=matching.appearance_pyramid,
    )


def _synthesize(state: State, config: DepthConfig) -> State:
    params = engine_params(sized_config(config, state.mask), state.mask, len(state.chosen))
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


def _complete_features(state: State, config: DepthConfig) -> State:
    exemplars = state.made("exemplars")
    state.source, completed = completion.complete_features(
        exemplars,
        state.made("source"),
        # The copy stage's example_ycbcr colours: their background is filled already.
        example_features(state, config, filled=True),
        state.mask,
        [example.mask for example in state.chosen],
        completion=config.completion,
    )
    log.info("small features completed: %d", completed)
    state.changed = f"{completed} small features copied whole"
    return state


def _position_factors(
    state: State, config: DepthConfig, levels: int, *, finest_only: bool = False
) -> list[np.ndarray | None] | None:
    """Per level of ``levels`` (finest first; only the finest with ``finest_only``), the
    query's factor on the position term: 1 where a registered example's relief agrees
    with the query's, less where the windows are to follow the query's own relief
    (:func:`position_scales`); None without it."""
    params = engine_params(sized_config(config, state.mask), state.mask, len(state.chosen))
    weights = [
        plan.position_weight if plan.position_weight is not None else params.position_weight
        for plan in params.level_plans(levels)
    ]
    return position_scales(
        relief_agreement(
            state.mask,
            state.warps,
            config.guides.relief_disagreement,
            config.registration.relief_detail_scale,
        ),
        weights[:1] if finest_only else weights,  # the coarser levels' pyramid: not made
        config.guides.position_weight,
    )


def _relief(state: State, config: DepthConfig) -> State:
    # Made here, for the seams, and not with the bands: full-size maps (the query's and
    # each example's relief, 12 bytes a pixel with two examples, and the seams' weights)
    # held through the synthesis, where the peak memory is, for nothing.
    if config.finish.seam_relief_weight > 0 and state.relief is None:  # else registered
        scale = config.registration.relief_detail_scale
        state.relief = (
            relief_detail(state.depth, state.mask, scale),
            [relief_detail(e.depth, e.mask, scale) for e in state.chosen],
        )
    # The seams weigh halfway (geometrically) between the registration's full weight and
    # the finest level's factor on the position term: with the factor itself 12 humans'
    # fragments for 90 % rose from 20-23 to 24-26 (seeds 0-2; the target is 25), with its
    # square root 23-24, and the scales at 768x576 keep a rim F1 of 0.95 (0.97 with the
    # factor, 0.89 at full weight everywhere).
    finest = state.finest_scale  # the bands' (the same mask and warps)
    if finest is None and state.warps:
        levels = sized_config(config, state.mask).pyramid.levels
        factors = _position_factors(state, config, levels, finest_only=True)
        finest = None if factors is None else factors[0]
    state.finest_scale = None
    state.seam_weights = None if finest is None else np.sqrt(finest)
    state.changed = (
        f"the relief's detail of the query and {len(state.chosen)} examples"
        if state.relief is not None
        else "no relief channel"
    ) + (", the seams' weights" if finest is not None else "")
    return state


def _unpose(state: State, config: DepthConfig) -> State:
    # The map back in the query's frame, and every source in its example's own pixels.
    frame: CanonicalFrame = state.made("frame")
    ycbcr, source = unpose(
        frame,
        state.query_depth > 0,
        state.made("ycbcr"),
        state.made("source"),
        state.exemplars,
    )
    for index, (example, flip) in enumerate(zip(state.chosen, state.mirrored, strict=True)):
        if flip:  # a mirrored example's column x is its own column width - 1 - x
            mine = source[..., 0] == index
            source[..., 2][mine] = example.shape[1] - 1 - source[..., 2][mine]
    if state.engine is not None:
        state.engine.cost = unpose_nearest(frame, state.query_depth.shape, state.engine.cost)
    state.ycbcr, state.source, state.exemplars = ycbcr, source, None
    state.depth, state.mask = state.query_depth, state.query_depth > 0
    state.changed = f"back in the query's frame ({state.mask.shape[1]}x{state.mask.shape[0]})"
    return state


def _warp_copy(state: State, config: DepthConfig) -> State:
    # warp_nearest: every pixel copied from the first example where its warp puts it
    # (an example pixel outside that example's object: its nearest object pixel's).
    example, warp = state.chosen[0], state.warps[0]
    ys, xs = np.mgrid[0 : state.mask.shape[0], 0 : state.mask.shape[1]].astype(np.float64)
    ey, ex = warp.forward(ys, xs)
    height, width = example.mask.shape
    iy = np.clip(np.rint(ey), 0, height - 1).astype(np.int64)
    ix = np.clip(np.rint(ex), 0, width - 1).astype(np.int64)
    # The registration's nearest object pixels where it kept them, else made here (the
    # indices only: SciPy's distances are three more (2, H, W) arrays); the colours' fill
    # reads the same.
    nearest = state.nearest[1] if len(state.nearest) > 1 else None
    state.nearest = []
    if nearest is None:
        nearest = nearest_object_pixels(example.mask)
    ny, nx = nearest
    source = np.stack([np.zeros_like(iy), ny[iy, ix], nx[iy, ix]], axis=-1).astype(np.int32)
    state.exemplars = [example_ycbcr(example, nearest)]
    del nearest, ny, nx
    state.source = source
    state.ycbcr = copy_through(state.exemplars, source).astype(np.float32)
    state.changed = f"{int(state.mask.sum())} pixels copied from {example.name}"
    return state


def _capped(config: DepthConfig) -> bool:
    return config.pyramid.search_size > 0


#: The pipeline, in order: the depth front end's own stages, then the shared finish
#: (:mod:`imagemap.depth.finish`) with the completion of small features, which reads the
#: relief, after the copy.
STAGES: tuple[Stage[State, DepthConfig], ...] = (
    Stage("select", _select),
    Stage("pose", _pose),
    Stage("working", _working, _capped),
    Stage("register", _register, lambda c: c.guides.registration),
    Stage("bands", _bands),
    Stage("synthesize", _synthesize),
    COLLAPSE,
    COPY,
    Stage(
        "complete_features",
        _complete_features,
        lambda c: c.finish.copies and c.finish.complete_features,
    ),
    Stage("relief", _relief, SEAMS.wanted),
    SEAMS,
    Stage("fine", _fine, _capped),
    OUTSIDE,
    BLEND,
    Stage("unpose", _unpose),
    RGB,
)

#: The ``warp_nearest`` baseline's stages: the first example posed and warped onto the
#: query as the method does, and copied whole (no synthesis).
WARP_NEAREST_STAGES: tuple[Stage[State, DepthConfig], ...] = (
    Stage("select", _select),
    Stage("pose", _pose),
    Stage("register", _register),
    Stage("warp_copy", _warp_copy),
    Stage("unpose", _unpose),
    RGB,
)


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
    config : DepthConfig
        The configuration that ran (its pyramid sized for the object).
    stages : list of StageRecord
        Per stage that ran: seconds and what it changed.
    engine_timings : dict
        The engine's own steps' seconds (``pca``, ``search``, ``vote``...), inside the
        ``synthesize`` stage's.
    poses : list of Pose
        Where the query lies against each example (turn, scale, mirrored;
        :mod:`imagemap.depth.pose`).
    """

    image: np.ndarray
    mask: np.ndarray
    source: np.ndarray
    cost: np.ndarray
    example_names: list[str]
    objective: list[list[float]]
    config: DepthConfig | None = None
    stages: list[StageRecord] = field(default_factory=list)
    engine_timings: dict[str, float] = field(default_factory=dict)
    poses: list[Pose] = field(default_factory=list)

    @property
    def timings(self) -> dict[str, float]:
        """Seconds per stage that ran, the ``synthesize`` stage given as the engine's
        own steps (``synthesize.pca``, ``synthesize.search``...) and the rest of it."""
        seconds: dict[str, float] = {}
        for record in self.stages:
            if record.changed == "off":
                continue
            if record.name == "synthesize" and self.engine_timings:
                inside = {f"synthesize.{k}": v for k, v in self.engine_timings.items()}
                seconds.update(inside)
                seconds["synthesize.other"] = max(record.seconds - sum(inside.values()), 0.0)
            else:
                seconds[record.name] = record.seconds
        return seconds

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
        from skimage import color  # deferred: start-up (only a provenance picture)

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


def _check_arguments(depth, database, examples, seed) -> list[str] | None:
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
    names = _check_arguments(depth, database, examples, seed)
    config = resolve_config(preset, **options)
    guard_colorize(depth, database, config, examples=names)
    depth = validate_depth(depth, copy=False)  # only read: the caller's array, not a copy
    if len(database) == 0:
        raise InputError("the database has no examples")
    return _run(depth, database, config, STAGES, names, seed, quiet)


def _run(depth, database, config, stages, names, seed, quiet) -> ColorizeResult:
    state = State(depth=depth, database=database, seed=seed, quiet=quiet, names=names)
    state, records = run_pipeline(state, config, stages)
    frame: CanonicalFrame = state.made("frame")
    # The configuration as it ran: its pyramid sized for the object in the synthesis'
    # frame (as many levels as its size calls for), averaged above the search size.
    searched = state.searched
    if searched is None:
        searched = resample_depth(state.query_depth, frame) > 0
    config = sized_config(config, searched)
    engine = state.engine
    return ColorizeResult(
        image=state.made("image"),
        mask=state.mask,
        source=state.made("source"),
        cost=engine.cost if engine else np.full(state.mask.shape, np.nan, np.float32),
        example_names=[e.name for e in state.chosen],
        objective=engine.objective if engine else [],
        config=config,
        stages=records,
        engine_timings=dict(engine.timings) if engine else {},
        poses=list(state.poses),
    )


def warp_nearest(
    depth: np.ndarray,
    database: Database,
    preset: str | DepthConfig | None = "busts",
    *,
    examples: list[str] | None = None,
    seed: int = 0,
    quiet: bool = True,
    **options: Any,
) -> ColorizeResult:
    """The baseline the method must beat: the first-choice example posed and warped
    onto the query as :func:`colorize` does it (:data:`WARP_NEAREST_STAGES`), then copied
    whole, without any synthesis. Arguments as :func:`colorize`.

    Examples
    --------
    See the module's example (``warp_nearest`` in place of ``colorize``).
    """
    names = _check_arguments(depth, database, examples, seed)
    config = resolve_config(preset, **options).replace_fields(m=1)
    depth = validate_depth(depth)
    if len(database) == 0:
        raise InputError("the database has no examples")
    return _run(depth, database, config, WARP_NEAREST_STAGES, names[:1] if names else None,
                seed, quiet)  # fmt: skip


colorize.__doc__ = (colorize.__doc__ or "").replace(
    "{options}", ", ".join(f"``{option.name}``" for option in OPTIONS)
)
