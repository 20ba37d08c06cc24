"""How the finest level's matches make the map: the finish stages, shared by every front
end that synthesizes colour maps (depth maps, and meshes in a shared UV atlas).

They read and write a :class:`SynthesisState`: the object's mask, the chosen examples
(each with a ``name``, a ``mask`` and an ``image``), the engine's result, and the map
being finished. A front end runs them after its own stages that make the engine's
result (``imagemap.depth.pipeline.STAGES``, ``imagemap.mesh.uvspace``).

=====================  ==================================================
stage                  what it does
=====================  ==================================================
``collapse``           the voted map at the finest level
``copy``               every pixel's source: the pixel its windows agree on
``seams``              a few whole copies, their seams where they agree
``outside``            the blend's reference outside the object: the copy
``blend``              the seams blended in the gradient domain
``rgb``                back to RGB, background 0
=====================  ==================================================
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
from scipy import ndimage

from imagemap.core.blend import copy_through
from imagemap.core.engine import EngineResult, ReleasableLevels
from imagemap.core.poisson import seamless_copy
from imagemap.core.pyramid import collapse_laplacian
from imagemap.core.seams import place_seams, with_channels
from imagemap.core.stages import Stage
from imagemap.depth import completion
from imagemap.depth.config import DepthConfig
from imagemap.depth.guides import example_ycbcr, to_rgb
from imagemap.depth.schedule import each_example

__all__ = [
    "BLEND",
    "COLLAPSE",
    "COPY",
    "OUTSIDE",
    "RGB",
    "SEAMS",
    "Exemplar",
    "Picture",
    "SynthesisState",
    "changed_pixels",
    "example_features",
]


class Exemplar(Protocol):
    """What the finish reads of a chosen example (an :class:`~imagemap.example.Example`
    or a :class:`Picture`)."""

    @property
    def name(self) -> str: ...
    @property
    def mask(self) -> np.ndarray: ...
    @property
    def image(self) -> np.ndarray: ...


@dataclass
class Picture:
    """A chosen example that is only a picture and its mask (a texture in a UV atlas)."""

    name: str
    image: np.ndarray
    mask: np.ndarray


@dataclass(kw_only=True)
class SynthesisState:
    """What the stages of a colour synthesis hand on to each other.

    A front end sets the inputs (``mask``, ``chosen``, ``seed``, ``quiet``) and its own
    stages make the engine's levels and its result (``engine``); each stage fills in what
    it makes and drops what no later stage needs, so that it does not add to the peak
    memory of the stages after it.
    """

    mask: np.ndarray  # the object
    chosen: list[Any] = field(default_factory=list)  # the examples: Exemplar
    seed: int = 0
    quiet: bool = True
    query_levels: ReleasableLevels | None = None  # the engine's inputs, handed over to it
    exemplar_levels: list[ReleasableLevels] | None = None
    engine: EngineResult | None = None
    ycbcr: np.ndarray | None = None  # the voted map, then the map being finished (YCbCr)
    exemplars: list[np.ndarray] | None = None  # the examples' colours the copy reads
    # The examples' example_ycbcr colours, where a front end kept them from its bands for
    # the copy stage (small frames), else None: the copy stage makes them.
    colours: list[np.ndarray] | None = None
    source: np.ndarray | None = None  # (H, W, 3): example, y, x of every pixel
    features: list[tuple[np.ndarray, int]] | None = None  # the examples' small features
    # The relief's detail of the query and of each example (a front end with depth sets
    # it): the seams then fall where the copies agree in colour and in relief.
    relief: tuple[np.ndarray, list[np.ndarray]] | None = None
    # Per pixel, a factor on the seams' weight: 1 where a registered example's relief
    # agrees with the query's, less where the windows follow the query's own relief (from
    # the finest level's factor on the position term,
    # :func:`imagemap.depth.register.position_scales`), or None.
    seam_weights: np.ndarray | None = None
    image: np.ndarray | None = None
    changed: str = ""  # what the last stage changed, for the record

    def made(self, name: str) -> Any:
        """The value of ``name`` that an earlier stage made (an error naming it if none did:
        a stage run out of order)."""
        value = getattr(self, name)
        if value is None:
            raise RuntimeError(f"pipeline: no stage has made {name!r} yet (stage order)")
        return value


def changed_pixels(old: np.ndarray, new: np.ndarray) -> int:
    """Pixels whose source differs between two source maps (by blocks of rows)."""
    if old is new:
        return 0
    count = 0
    for y in range(0, old.shape[0], 256):
        count += int(np.count_nonzero((old[y : y + 256] != new[y : y + 256]).any(axis=-1)))
    return count


def example_features(
    state: SynthesisState, config: DepthConfig, *, filled: bool = False
) -> list[tuple[np.ndarray, int]]:
    """The chosen examples' small features (:func:`completion.small_features`), found once
    (``filled``: the exemplars are :func:`~imagemap.depth.guides.example_ycbcr`'s, their
    background filled already, as the copy stage makes them)."""
    if state.features is None:
        pairs = list(zip(state.made("exemplars"), state.chosen, strict=True))
        found: dict[int, tuple[np.ndarray, int]] = {}

        def find(index: int) -> None:
            exemplar, example = pairs[index]
            found[index] = completion.small_features(
                exemplar, example.mask, completion=config.completion, filled=filled
            )

        # Each example's on the kernels' threads (the hosts' median filter and distances
        # release the GIL), in example order: the same labels.
        each_example(find, [exemplar.shape for exemplar, _ in pairs])
        state.features = [found[index] for index in range(len(pairs))]
    return state.features


def _collapse(state: SynthesisState, config: DepthConfig) -> SynthesisState:
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


def _copy(state: SynthesisState, config: DepthConfig) -> SynthesisState:
    # Every pixel copied from the exemplar pixel its windows agree on. The examples'
    # colours are made again rather than kept from the pyramids: full-size arrays held
    # through the synthesis would add to its peak memory, and they cost little to remake.
    engine: EngineResult = state.made("engine")
    if state.colours is not None:  # kept from the bands: the same colours
        state.exemplars, state.colours = state.colours, None
    else:
        state.exemplars = [example_ycbcr(example) for example in state.chosen]
    copied = state.source = engine.copy_source
    differ = 0 if copied is None else changed_pixels(engine.source, copied)
    engine.source = engine.copy_source = None  # type: ignore[assignment]  # handed over
    state.changed = f"{differ} pixels copied from another source than their window's match"
    return state


def _seams(state: SynthesisState, config: DepthConfig) -> SynthesisState:
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
    kept = completion.copies_features(old, example_features(state, config)) | (shown > 0)
    del shown
    size = float(np.sqrt(state.mask.sum()))
    reference = state.made("ycbcr")
    # The extra channels of each copy, added by place_seams once it has cut the copies to
    # what the labels can read (full-size copies with five channels were the stage's
    # peak at 4096^2), and of the reference, in one allocation.
    extra: list[list] = [[] for _ in exemplars]
    reference_extra: list = []
    weight = config.finish.seam_relief_weight
    if state.relief is not None and weight > 0:
        # The relief as one more channel of the copies and of the reference: a copy whose
        # relief disagrees with the query's costs, and so does a seam across relief.
        query_relief, example_reliefs = state.relief
        for planes, relief in zip(extra, example_reliefs, strict=True):
            planes.append((weight, relief))
        reference_extra.append((weight, query_relief))
    preference = config.finish.seam_example_preference
    if preference > 0 and len(exemplars) > 1:
        # The examples' order as one more channel, constant per example (sqrt of its rank
        # times the preference; the reference's 0): a copy from a later example costs that
        # much a pixel, so the relief alone does not hand a part to another palette.
        for rank, planes in enumerate(extra):
            planes.append((np.sqrt(preference * rank), None))
        reference_extra.append((0.0, None))
    if reference_extra:
        reference = with_channels(reference, reference_extra)
    new = place_seams(
        exemplars,
        old,
        reference,
        smoothness=config.finish.seam_smoothness * size / 100.0,
        spread=config.finish.seam_spread,
        mask=state.mask,
        exemplar_masks=[example.mask for example in state.chosen],
        groups=ndimage.label(kept & state.mask)[0],
        coarse_above=config.finish.seam_coarse_above or None,
        band=config.finish.seam_band,
        # Where no registered example's relief agrees with the query's, the matches follow
        # the query's own relief (the position gave way there): the seams weigh less, and
        # do not merge those matches back into the examples' layout.
        weights=state.seam_weights,
        exemplar_channels=extra if reference_extra else None,
    )
    # The relief and the weights: not held through the blend.
    state.source, state.relief, state.seam_weights = new, None, None
    state.changed = f"{changed_pixels(old, new)} pixels take another source"
    return state


_ROWS = 256  # rows per block where the finish works row by row (no full-size float64 copy)


def _outside(state: SynthesisState, config: DepthConfig) -> SynthesisState:
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


def _blend(state: SynthesisState, config: DepthConfig) -> SynthesisState:
    size = float(np.sqrt(state.mask.sum()))
    scale = max(config.finish.blend_scale * size, 1.0)
    reference = state.made("ycbcr")
    writable = reference.dtype == np.float32 and reference.flags.writeable
    state.ycbcr = seamless_copy(
        state.made("exemplars"),
        state.made("source"),
        reference,
        scale=scale,
        edge_support=config.finish.edge_support,
        edge_contrast=config.finish.edge_contrast,
        edge_floor=config.finish.edge_floor,
        mask=state.mask,
        # The blended map written over the map being finished (no later stage reads it):
        # not a second full-size float32 map beside the solve, the finish's peak.
        out=reference if writable else None,
    )
    state.exemplars = None
    state.changed = f"seams blended at scale {scale:.1f} px"
    return state


def _rgb(state: SynthesisState, config: DepthConfig) -> SynthesisState:
    image = to_rgb(state.made("ycbcr"))
    image[~state.mask] = 0.0
    state.image, state.ycbcr = image, None
    state.changed = "RGB"
    return state


def _copies(config: DepthConfig) -> bool:
    return config.finish.copies


COLLAPSE: Stage[Any, DepthConfig] = Stage("collapse", _collapse)
COPY: Stage[Any, DepthConfig] = Stage("copy", _copy, _copies)
SEAMS: Stage[Any, DepthConfig] = Stage(
    "seams", _seams, lambda c: c.finish.copies and c.finish.seam_smoothness > 0
)
OUTSIDE: Stage[Any, DepthConfig] = Stage("outside", _outside, _copies)
BLEND: Stage[Any, DepthConfig] = Stage("blend", _blend, _copies)
RGB: Stage[Any, DepthConfig] = Stage("rgb", _rgb)
