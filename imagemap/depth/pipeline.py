"""Depth-map colorization: the first front end of the engine (Hassner & Basri 2006).

Guide bands per pyramid level: the depth's Gaussian level and its high
frequencies (the Laplacian band of the same level). Appearance bands: the Y, Cb
and Cr of the image-map at each level of its Gaussian pyramid, synthesised level
by level; the finest level's matches are copied into the map and the seams
blended. The paper's Laplacian colour bands (collapsed at the end) are
``appearance_pyramid="laplacian"``.

Examples
--------
>>> from imagemap import Database, colorize
>>> db = Database.from_directory("examples/fish")            # doctest: +SKIP
>>> result = colorize(query_depth, db, preset="fish", seed=0)  # doctest: +SKIP
>>> result.image.shape, result.example_names                  # doctest: +SKIP
((150, 200, 3), ['fish_003', 'fish_005'])
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np
from scipy import ndimage
from skimage import color

from imagemap.align import centroid as _centroid
from imagemap.align import centroid_shift, translate
from imagemap.core.blend import (
    copy_through,
    fill_background,
    merge_regions,
    place_seams,
    seamless_copy,
)
from imagemap.core.engine import (
    APPEARANCE_PYRAMIDS,
    EngineParams,
    EngineResult,
    Mapping,
    ReleasableLevels,
    synthesize,
)
from imagemap.core.pyramid import (
    collapse_laplacian,
    gaussian_pyramid,
    laplacian_pyramid,
    mask_pyramid,
)
from imagemap.database import Database, Example
from imagemap.depth import completion, palettes
from imagemap.io import InputError, validate_depth
from imagemap.validate import check_colorize_arguments, check_float, check_int

__all__ = [
    "PRESETS",
    "VOTES",
    "ColorizeParams",
    "ColorizeResult",
    "colorize",
    "depth_mappings",
    "example_mappings",
    "pyramid_levels",
    "context_level_weights",
    "context_levels",
    "select_examples",
    "translate",
    "centroid_shift",
]

log = logging.getLogger("imagemap")

#: How matched windows make the map (see :class:`ColorizeParams`).
VOTES = ("copy", "mean", "mode")


@dataclass(frozen=True)
class ColorizeParams:
    """Parameters of depth-map colorization.

    The six weights are those of the paper's Table 1 (depth, depth high
    frequencies, Y, Cb, Cr, relative position) restated for our units: each band
    weight is per standard deviation of that band over the selected examples at
    that pyramid level (so depth in metres, millimetres or [0, 1] gives the same
    result), and the position weight is per RMS radius of the object's pixel
    coordinates. See ``docs/presets.md`` for how the presets
    were set.

    Parameters
    ----------
    m : int
        Number of examples selected automatically.
    patch_sizes : tuple of int
        Window width per level, fine to coarse (three levels).
    depth_weight, depth_detail_weight : float
        Weights of the depth's Gaussian and Laplacian bands.
    luma_weight, chroma_weight : float
        Weights of Y and of Cb, Cr.
    position_weight : float
        Weight of the position relative to the depth's centroid.
    backend : str
        Search backend of the engine (``"patchmatch"``, ``"exact"``, ``"pynndescent"``).
    appearance_pyramid : {"gaussian", "laplacian"}
        What the engine synthesises and matches at each level: ``"gaussian"``
        (default) the plain YCbCr colours of that level, ``"laplacian"`` the
        paper's YCbCr Laplacian bands, collapsed at the end. A Laplacian band holds
        only the level's own frequencies, so at the finest level a match is free
        in every colour the coarser levels decided: the copy then takes
        trousers where the coarser levels drew skin, or another example's palette
        in the middle of a flank, and the seam blend turns the disagreement into a
        smear. With plain colours every level's matches carry the colours they
        copy. On the generated classes (12 objects each, seed 0) plain colours
        raised macro part transfer (fish 0.762 to 0.776, busts 0.709 to 0.807,
        humans 0.785 to 0.810), busts with every feature 83 to 92 %, and the
        blur ratio (fish 0.89 to 0.93, busts 0.84 to 0.88); at 4x busts drew 87 %
        of their features instead of 67 % (see ``docs/presets.md``).
    example_preference : float
        Extra window cost per rank of an example in the selection (the nearest
        example costs nothing, the second this much...), at the levels coarser
        than the one that draws the small features (the finest at the paper's
        size; on a large map the finest whose window spans ``CONTEXT_FRACTION`` of
        the object) unless ``preference_at_finest``: the coarse levels then take
        each region of the object from one example where it fits nearly as well
        (no patch of the second example's palette in the middle of a shirt or a
        flank), and the feature level still takes a small feature from whichever
        example draws it. 0 is the paper's method.
    preference_at_finest : bool
        Apply the preference at the feature level and the finer levels too: fewer
        and smaller seams (crisper), fewer small features.
    vote : {"copy", "mean", "mode"}
        How the matched windows make the map. ``"mean"``: the paper's M-step, every
        pixel the Gaussian-weighted mean of its windows' estimates (smooth, and
        blurred where they disagree). ``"copy"`` (default): the same hard EM, then
        every pixel copied from the exemplar pixel most of its windows agree on,
        with the seams between sources blended in the gradient domain
        (:func:`imagemap.core.blend.seamless_copy`): crisp stripes, edges and eyes.
        ``"mode"``: copying already inside the EM iterations (the engine's
        ``vote="mode"``), then the same finish.
    blend_scale : float
        How far a copied map may drift towards the voted colours (seam blending),
        as a fraction of the object's size (square root of its area): 0.1 is 8 px
        for the generated 200x150 fish and 85 px for a 2048² one, so the copy, not
        the blurrier vote, holds the colours at every scale below a tenth of the
        object. Larger keeps more of the copy.
    seam_smoothness : float
        Weight of the seam costs when the copy's sources are rearranged so that
        seams fall where the sources agree (:func:`imagemap.core.blend.place_seams`; 0:
        off).
    grow_pyramid : bool
        Add pyramid levels for large objects (see :func:`pyramid_levels`); False
        keeps the preset's levels (dropping them still for small objects).
    detail_clip : float
        The depth detail band is measured in units of its robust spread inside the
        object and soft-clipped at this many units (0: raw band). Without it the
        silhouette's jump sets the band's scale and interior relief (eye sockets,
        lips, an eye's bulge) hardly counts.
    silhouette_weight : float
        Weight of the silhouette band: the signed distance to the object's outline
        in pixels of each level, clipped at ``SILHOUETTE_RANGE``. With it the depth
        bands see the depth extended smoothly past the outline, so a window at the
        edge matches the relief it holds (an eye close to the outline) rather than
        the jump to background; 0 keeps the paper's bands (the jump marks the edge).
    guide_reseed : float
        Per level, where the propagated matches fit the depth worst, matches on
        depth and position alone replace them when they fit in less than this
        fraction of the distance (the engine's ``guide_reseed``; 0: off). Features
        that only the finer levels resolve are then drawn.
    final_reseed : float
        After the finest level's EM, where its matches fit the depth worst (a
        quarter of the windows), matches on depth and position alone replace them
        for the copy when they fit in less than this fraction of the distance and
        carry at least as much appearance detail (the engine's ``final_reseed``;
        0: off; not with ``vote="mean"``, whose map is the EM's vote). Where the
        finest window spans less than ``CONTEXT_FRACTION`` of the object (a large
        map), whose relief it cannot tell apart there, it follows the EM of the
        finest level whose window spans that much, and the finer levels start from
        its matches (the engine's ``feature_level``).
        The EM keeps what the coarser levels drew, and an eye or lips they blurred
        away fit no window of the blurred estimate: the copy then takes them where
        the relief says. On 36 generated busts (seed 1) 0.7 drew 91 % of eyes,
        eyebrows and lips instead of 83 %, every feature in 67 % of busts instead
        of 50 %, and raised macro part transfer 0.662 to 0.715; on the 12 of seed
        0 the blur ratio fell 0.86 to 0.84. An eye it draws may come from the
        other example than its twin (another iris colour).
    context_weight : float
        Weight of the coarser levels' luminance as an extra guide band (times the Y
        weight; the engine's ``context_weights``; Cb and Cr too gave the same maps
        for about 10 % more peak memory at 1024²) at the levels whose
        window spans less than ``CONTEXT_FRACTION`` of the object's size (see
        :func:`context_levels`): on a large map the fine levels then keep the eyes,
        lips and palette the coarser levels chose instead of matching their own thin
        band alone (0: off). At the paper's 200x150 no level is that fine.
    wide_context_weight : float
        The context's weight (a factor on ``context_weight``) at the other levels
        but the coarsest, where windows span more of the object (every level with
        context at 200x150; see :func:`context_level_weights`). Weak, so that the
        level's own band still draws the small features, while the coarser colours
        decide between examples whose bands fit alike: at 200x150 busts then draw
        every feature in 83 % of objects instead of 75 %, and the copy switches
        palette less often (blur ratio fish 0.87 to 0.90, busts 0.74 to 0.86).
        Full weight there lost fish eyes; 0: the paper's bands at those levels.
    merge_regions : bool
        After the seam placement, let whole stray patches of another source that
        sit off the voted colours take a touching region's source
        (:func:`imagemap.core.blend.merge_regions`). Off by default: on the generated
        classes it raised the blur ratio (fish 0.87 to 0.89, busts 0.74 to 0.78)
        but lost bust features (objects with all features 75 % to 67 %); see
        ``docs/presets.md``.
    keep_detail : float
        The share of a region's luminance detail a merge must keep (0 to 1).
    complete_features : bool
        After the seams are placed, copy whole every small feature of an example
        (an eye, lips, a brow: found from its colours, see
        :mod:`imagemap.depth.completion`) that the map copies only in part, at the mean
        offset of the part: two offsets meeting inside lips had left a lozenge of
        lips. On the generated classes (12 objects, seed 0) busts drew every
        feature in 100 % of objects instead of 92 %, and at 4x the size in 83 %
        instead of 67 % (6 busts); fish and humans were unchanged (see
        ``docs/presets.md``). Only with ``vote`` "copy" or "mode".
    edge_support : float
        Where the copy changes source within one example, keep its own step if
        it is an edge (twice as strong as the texture on either side) and the
        voted map shows the same change, over the four pixels around it, at this
        share of its size or more (:func:`imagemap.core.blend.seamless_copy`; 0: every
        seam blended). A part boundary that falls on a seam (a sleeve from one
        place, the hand from another) then stays one pixel sharp instead of being
        spread over the blend scale. 0.3 accepts the voted edge up to about two
        pixels from the copy's (the vote's edges are a finest window wide); steps
        between two examples are palette differences and always blended. On the
        generated classes (12 objects, seed 0) it raised the blur ratio (fish
        0.93 to 0.97, busts 0.88 to 0.91, humans 0.88 to 0.97) for 0.002 to
        0.004 of SSIM (see ``docs/presets.md``).
    even_palettes : bool
        Where the copy shows one part (a face's skin, a plain shirt) in two
        examples' colours, shift the smaller share into the larger's colours
        before the blend (:func:`imagemap.depth.palettes.even_palettes`): one skin
        tone from face to neck instead of two. Only solid parts found in the
        same place and nearest in colour in both examples are shifted, never a
        pattern's colours or a small feature. Needs ``m`` >= 2; only with
        ``vote`` "copy" or "mode". Off by default: on the generated classes no
        detail measure moves, SSIM by 0.001 at most, and busts' ΔE00 rises (+0.45
        on 12), while the faces it evens look right (``docs/presets.md``).
    """

    m: int = 2
    patch_sizes: tuple[int, ...] = (7, 11, 9)
    depth_weight: float = 1.0
    depth_detail_weight: float = 2.0
    luma_weight: float = 1.0
    chroma_weight: float = 0.5
    position_weight: float = 1.0
    pca_fraction: float = 0.2
    backend: str = "patchmatch"
    max_iterations: int = 8
    tolerance: float = 2e-3
    appearance_pyramid: str = "gaussian"
    example_preference: float = 0.3
    preference_at_finest: bool = False
    vote: str = "copy"
    blend_scale: float = 0.1
    seam_smoothness: float = 1.0
    detail_clip: float = 3.0
    grow_pyramid: bool = True
    silhouette_weight: float = 0.5
    guide_reseed: float = 0.5
    final_reseed: float = 0.7
    context_weight: float = 1.0
    wide_context_weight: float = 0.25
    merge_regions: bool = False
    keep_detail: float = 0.5
    complete_features: bool = True
    edge_support: float = 0.3
    even_palettes: bool = False

    def __post_init__(self) -> None:
        if self.vote not in VOTES:
            raise InputError(f"unknown vote {self.vote!r}; use one of {VOTES}")
        if self.appearance_pyramid not in APPEARANCE_PYRAMIDS:
            raise InputError(
                f"unknown appearance_pyramid {self.appearance_pyramid!r}; "
                f"use one of {APPEARANCE_PYRAMIDS}"
            )
        check_float("context_weight", self.context_weight, minimum=0.0)
        check_float("wide_context_weight", self.wide_context_weight, minimum=0.0)
        check_float("keep_detail", self.keep_detail, minimum=0.0, maximum=1.0)
        check_float("edge_support", self.edge_support, minimum=0.0, maximum=1.0)
        check_float("silhouette_weight", self.silhouette_weight, minimum=0.0)
        if check_float("guide_reseed", self.guide_reseed, minimum=0.0, maximum=1.0) == 1.0:
            raise InputError("guide_reseed: must be below 1 (a fraction of the distance)")
        if check_float("final_reseed", self.final_reseed, minimum=0.0, maximum=1.0) == 1.0:
            raise InputError("final_reseed: must be below 1 (a fraction of the distance)")

    @property
    def levels(self) -> int:
        return len(self.patch_sizes)

    def engine_params(
        self, n_examples: int = 0, context_levels: int = 0, context_level_weights=()
    ) -> EngineParams:
        costs = tuple(self.example_preference * rank for rank in range(n_examples))
        return EngineParams(
            exemplar_costs=costs if self.example_preference else (),
            exemplar_costs_at_finest=self.preference_at_finest,
            patch_sizes=self.patch_sizes,
            guide_weights=(self.depth_weight, self.depth_detail_weight)
            + ((self.silhouette_weight,) if self.silhouette_weight else ()),
            appearance_weights=(self.luma_weight, self.chroma_weight, self.chroma_weight),
            position_weight=self.position_weight,
            pca_fraction=self.pca_fraction,
            backend=self.backend,
            max_iterations=self.max_iterations,
            tolerance=self.tolerance,
            guide_padding="constant",
            vote="mode" if self.vote == "mode" else "mean",
            guide_reseed=self.guide_reseed,
            # The mean vote's map is the EM's own vote: matches changed after it would
            # describe (source, provenance) a map that was not made from them.
            final_reseed=self.final_reseed if self.vote != "mean" else 0.0,
            context_weights=(
                (self.context_weight * self.luma_weight, 0.0, 0.0)
                if self.context_weight and context_levels
                else ()
            ),
            context_levels=context_levels,
            context_level_weights=tuple(context_level_weights),
            appearance_pyramid=self.appearance_pyramid,
        )


#: Class presets after the paper's Table 1 (m and patch widths as published;
#: weights restated per band standard deviation, see ``docs/presets.md``).
PRESETS: dict[str, ColorizeParams] = {
    "humans": ColorizeParams(m=1, patch_sizes=(7, 9, 9), position_weight=3.0),
    "busts": ColorizeParams(m=2, patch_sizes=(7, 11, 9), position_weight=1.0),
    "fish": ColorizeParams(m=2, patch_sizes=(7, 11, 9), position_weight=0.5),
}


def _resolve(preset: str | ColorizeParams | None, **overrides) -> ColorizeParams:
    if preset is None:
        params = ColorizeParams()
    elif isinstance(preset, ColorizeParams):
        params = preset
    else:
        try:
            params = PRESETS[preset]
        except KeyError:
            raise InputError(f"unknown preset {preset!r}; use one of {sorted(PRESETS)}") from None
    overrides = {k: v for k, v in overrides.items() if v is not None}
    return replace(params, **overrides) if overrides else params


def select_examples(depth: np.ndarray, database: Database, m: int = 2) -> list[int]:
    """Indices of the ``m`` examples whose depth is nearest to ``depth`` after centroid alignment.

    The distance is the sum of squared differences once each example's depth is
    translated so that its foreground centroid falls on the query's (paper, Sec. 2.3).

    Examples
    --------
    >>> select_examples(query_depth, db, m=2)  # doctest: +SKIP
    [3, 5]
    """
    m = check_int("m", m, minimum=1)
    depth = validate_depth(depth)
    # SSD over the query frame plus the example's depth that falls outside it (a larger
    # object is a worse fit) = |D|^2 + |Di|^2 - 2 <D, shifted Di> over their overlap, with
    # each example's centroid and |Di|^2 computed once (Example.selection_stats).
    query_centroid = _centroid(depth > 0)
    query_norm = float(np.square(depth, dtype=np.float64).sum())
    height, width = depth.shape
    distances = []
    for example in database:
        other = example.depth
        centroid, other_norm = example.selection_stats
        dy, dx = (int(round(s)) for s in query_centroid - centroid)
        y0, x0 = max(0, dy), max(0, dx)
        y1, x1 = min(height, other.shape[0] + dy), min(width, other.shape[1] + dx)
        cross = 0.0
        if y1 > y0 and x1 > x0:
            here = depth[y0:y1, x0:x1]
            there = other[y0 - dy : y1 - dy, x0 - dx : x1 - dx]
            # Not a BLAS dot: a multithreaded BLAS spins on a busy machine (15 ms a call).
            cross = float(np.multiply(here, there, dtype=np.float64).sum())
        distances.append(query_norm + other_norm - 2.0 * cross)
    order = np.argsort(distances, kind="stable")
    return [int(i) for i in order[:m]]


#: The coarsest level must see the object at least this many windows across.
MIN_WINDOWS_ACROSS = 1.25
#: A level is added while the next coarser one would still see the object this many
#: windows across (the paper's 200x150 objects are about 2 to 3.5 windows across at
#: its coarsest level): large maps get the pyramid their size calls for, and their
#: coarsest level sees the object's layout as the paper's does (3.5 left busts at 4x
#: with a coarsest level twice as fine as at 200x150: hair over the brows).
ADD_WINDOWS_ACROSS = 3.0


#: A level whose window spans less than this fraction of the object's size (square
#: root of its area) gets the coarser levels' colours as context. At 200x150 (objects
#: 70-130 px) the finest window spans 0.05-0.1: no context, the paper's levels; at
#: 800x600 the two finest levels of a bust (0.014, 0.029) or a fish. The finest level
#: that spans more draws the features (the engine's ``feature_level``).
CONTEXT_FRACTION = 0.05


def context_levels(mask: np.ndarray, patch_sizes: tuple[int, ...]) -> int:
    """How many of the finest levels see the coarser levels' colours (see ``CONTEXT_FRACTION``).

    Examples
    --------
    >>> small = np.zeros((150, 200), bool); small[30:120, 50:150] = True
    >>> context_levels(small, (7, 11, 9))
    0
    >>> big = np.zeros((600, 800), bool); big[100:500, 100:700] = True
    >>> context_levels(big, (7, 11, 9, 9))
    2
    """
    size = float(np.sqrt(mask.sum()))
    spans = [k * 2**level / size for level, k in enumerate(patch_sizes[:-1])]
    return sum(1 for span in spans if span < CONTEXT_FRACTION)


def context_level_weights(
    mask: np.ndarray, patch_sizes: tuple[int, ...], wide: float = 0.0
) -> tuple[int, tuple[float, ...]]:
    """Which levels see the coarser levels' colours, and how strongly.

    Returns the number of the finest levels with context and a factor per level
    (finest first) on ``context_weight``: 1 where a window spans less than
    ``CONTEXT_FRACTION`` of the object (its own band holds almost nothing of the
    object's structure there), ``wide`` at the other levels but the coarsest.

    Examples
    --------
    >>> small = np.zeros((150, 200), bool); small[30:120, 50:150] = True
    >>> context_level_weights(small, (7, 11, 9), wide=0.25)
    (2, (0.25, 0.25, 0.0))
    >>> big = np.zeros((600, 800), bool); big[100:500, 100:700] = True
    >>> context_level_weights(big, (7, 11, 9, 9), wide=0.25)
    (3, (1.0, 1.0, 0.25, 0.0))
    >>> context_level_weights(small, (7, 11, 9))
    (0, (0.0, 0.0, 0.0))
    """
    fine = context_levels(mask, patch_sizes)
    n = len(patch_sizes)
    weights = [1.0 if level < fine else float(wide) for level in range(n - 1)] + [0.0]
    count = max((level + 1 for level, w in enumerate(weights) if w > 0), default=0)
    return count, tuple(weights)


def pyramid_levels(mask: np.ndarray, patch_sizes: tuple[int, ...], grow: bool = True) -> int:
    """How many pyramid levels the object's size calls for.

    The object's size is the square root of its area. A preset's coarsest level
    is dropped while the object, at that level, is less than
    ``MIN_WINDOWS_ACROSS`` windows across (a window larger than the object
    matches nothing but the silhouette); levels are added while the next coarser
    level would still see the object ``ADD_WINDOWS_ACROSS`` windows across, so that
    the coarsest level sees the object's layout at any resolution as at the paper's
    size (the added levels are finer ones, see :func:`level_patch_sizes`). The
    paper's three levels and 7/11/9 windows were set for 200x150 images; this keeps
    them there.

    Examples
    --------
    >>> mask = np.zeros((60, 80), bool); mask[20:40, 10:70] = True
    >>> pyramid_levels(mask, (7, 11, 9))
    2
    >>> big = np.zeros((600, 800), bool); big[100:500, 100:700] = True
    >>> pyramid_levels(big, (7, 11, 9))
    5
    """
    size = float(np.sqrt(mask.sum()))
    levels = len(patch_sizes)
    while levels > 1 and size / 2 ** (levels - 1) < MIN_WINDOWS_ACROSS * patch_sizes[levels - 1]:
        levels -= 1
    if grow and levels == len(patch_sizes):
        while size / 2**levels >= ADD_WINDOWS_ACROSS * patch_sizes[-1]:
            levels += 1
    return levels


def level_patch_sizes(patch_sizes: tuple[int, ...], levels: int) -> tuple[int, ...]:
    """The preset's window widths (finest first) cut or extended to ``levels``.

    Levels added for a large object are finer ones: the preset's widths stay at the
    levels that see the object as its finest to coarsest levels do at the paper's
    size, and the added levels below repeat its finest width.

    Examples
    --------
    >>> level_patch_sizes((7, 11, 9), 5)
    (7, 7, 7, 11, 9)
    >>> level_patch_sizes((7, 11, 9), 2)
    (7, 11)
    """
    if levels <= len(patch_sizes):
        return tuple(patch_sizes[:levels])
    return (patch_sizes[0],) * (levels - len(patch_sizes)) + tuple(patch_sizes)


#: Percentile of |detail| inside the object taken as the detail band's unit: the
#: relief that marks features (an eye's bulge, sockets, lips), not the body's flat
#: stretches, whose tiny values a median would blow up into noise to match on.
DETAIL_PERCENTILE = 95.0


def _interior_scale(detail: np.ndarray, mask: np.ndarray) -> float:
    """The detail band's unit: its 95th percentile of magnitude inside the object."""
    inner = ndimage.binary_erosion(mask, iterations=2) if mask.any() else mask
    values = detail[inner] if inner.sum() >= 16 else detail[mask] if mask.any() else detail
    scale = float(np.percentile(np.abs(values), DETAIL_PERCENTILE)) if values.size else 0.0
    return scale if scale > 0 else max(float(np.abs(detail).max()), 1e-12)


#: The silhouette band saturates this many pixels (of each level) inside and
#: outside the outline: it says "edge here" to a window, not how deep inside it is.
SILHOUETTE_RANGE = 2.0
#: Smoothing (pixels) of the depth extended past the outline.
EXTENSION_SIGMA = 2.0


def _extend_depth(depth: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """The depth continued past the outline: nearest object depth, smoothed outside.

    Windows at the outline then compare relief with relief; the outline itself
    is the silhouette band's job.
    """
    outside = ndimage.gaussian_filter(fill_background(depth, mask), EXTENSION_SIGMA)
    return np.where(mask, depth, outside).astype(np.float32)


def _silhouette_band(mask: np.ndarray) -> np.ndarray:
    """Signed distance to the outline (positive inside), clipped at SILHOUETTE_RANGE."""
    inside = ndimage.distance_transform_edt(mask)
    outside = ndimage.distance_transform_edt(~mask)
    signed = (inside - outside) / SILHOUETTE_RANGE
    return np.clip(signed, -1.0, 1.0).astype(np.float32)


def _depth_guides(
    depth: np.ndarray, masks: list[np.ndarray], clip: float | None = None, silhouette: bool = False
) -> list[np.ndarray]:
    """Per level of ``masks`` (the object's mask pyramid): (H_l, W_l, B) depth Gaussian
    level, its Laplacian (detail) band and, with ``silhouette``, the silhouette band (the
    depth then extended past the outline)."""
    levels = len(masks)
    if silhouette:
        depth = _extend_depth(depth, masks[0])
    gaussian = gaussian_pyramid(depth, levels)
    # One level more, so that even the coarsest level has a true band-pass detail band.
    detail = laplacian_pyramid(depth, levels + 1)[:levels]
    if clip:
        scaled = []
        for d, m in zip(detail, masks, strict=True):
            unit = _interior_scale(d, m)
            scaled.append((clip * unit) * np.tanh(d / (clip * unit)))
        detail = scaled
    bands = [[g, d] for g, d in zip(gaussian, detail, strict=True)]
    if silhouette:
        for level_bands, m in zip(bands, masks, strict=True):
            level_bands.append(_silhouette_band(m))
    return [np.stack(level_bands, axis=-1) for level_bands in bands]


def depth_mappings(
    depth: np.ndarray, levels: int = 3, clip: float | None = None, silhouette: bool = False
) -> list[Mapping]:
    """The query's pyramid of mappings (guide bands and mask) for a depth map."""
    depth = validate_depth(depth)
    masks = mask_pyramid(depth > 0, levels)
    return [
        Mapping(guide=guide, mask=mask if mask.any() else None)
        for guide, mask in zip(_depth_guides(depth, masks, clip, silhouette), masks, strict=True)
    ]


_ROWS = 256  # rows per block of the colour conversions


def to_ycbcr(rgb: np.ndarray) -> np.ndarray:
    """RGB in [0, 1] to YCbCr scaled to [0, 1] (ITU-R BT.601, as skimage)."""
    # In blocks of rows: skimage works in float64 (several full-size copies at 4096^2).
    out = np.empty(rgb.shape, dtype=np.float32)
    for y in range(0, rgb.shape[0], _ROWS):
        out[y : y + _ROWS] = color.rgb2ycbcr(rgb[y : y + _ROWS]) / 255.0
    return out


def to_rgb(ycbcr: np.ndarray) -> np.ndarray:
    """Inverse of :func:`to_ycbcr`, clipped to [0, 1]."""
    return np.clip(color.ycbcr2rgb(ycbcr.astype(np.float64) * 255.0), 0.0, 1.0).astype(np.float32)


def _example_ycbcr(example: Example) -> np.ndarray:
    # The image read from disk is not left cached on the example: the synthesis keeps
    # only its colour bands, and the finish reads it again (a full-size float32 image
    # per example less through the synthesis).
    cache = getattr(example, "__dict__", {})
    cached = "image" in cache
    image = example.image
    if not cached and "image" in cache:  # filled just now (a cached_property): emptied
        del cache["image"]
    return to_ycbcr(fill_background(image, example.mask))


def example_mappings(
    example: Example,
    levels: int = 3,
    appearance_pyramid: str = "gaussian",
    clip: float | None = None,
    silhouette: bool = False,
) -> list[Mapping]:
    """An example's pyramid of mappings: depth bands, YCbCr (Gaussian or Laplacian) levels, mask."""
    if appearance_pyramid not in APPEARANCE_PYRAMIDS:  # the old use_pyramid bool included
        raise ValueError(f"appearance_pyramid must be one of {APPEARANCE_PYRAMIDS}")
    mask = example.mask
    ycbcr = _example_ycbcr(example)
    if appearance_pyramid == "laplacian":
        appearance = laplacian_pyramid(ycbcr, levels)
    else:
        appearance = gaussian_pyramid(ycbcr, levels)
    masks = mask_pyramid(mask, levels)
    return [
        Mapping(guide=guide, appearance=bands, mask=level_mask if level_mask.any() else None)
        for guide, bands, level_mask in zip(
            _depth_guides(example.depth, masks, clip, silhouette), appearance, masks, strict=True
        )
    ]


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
        Seconds per stage.
    """

    image: np.ndarray
    mask: np.ndarray
    source: np.ndarray
    cost: np.ndarray
    example_names: list[str]
    objective: list[list[float]]
    timings: dict[str, float] = field(default_factory=dict)
    params: ColorizeParams | None = None

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
        return [
            (name, tuple(float(c) for c in _PALETTE[i % len(_PALETTE)]))
            for i, name in enumerate(self.example_names)
        ]


def colorize(
    depth: np.ndarray,
    database: Database,
    preset: str | ColorizeParams | None = "busts",
    *,
    m: int | None = None,
    examples: list[str] | None = None,
    backend: str | None = None,
    example_preference: float | None = None,
    vote: str | None = None,
    appearance_pyramid: str | None = None,
    edge_support: float | None = None,
    complete_features: bool | None = None,
    even_palettes: bool | None = None,
    seed: int = 0,
    quiet: bool = True,
) -> ColorizeResult:
    """Synthesise an image-map for ``depth`` from the examples of ``database``.

    Parameters
    ----------
    depth : ndarray, (H, W)
        Query depth; larger is nearer, 0 or NaN is background.
    database : Database
        Examples of the same class.
    preset : str or ColorizeParams
        ``"humans"``, ``"busts"``, ``"fish"`` or explicit parameters.
    m : int, optional
        Number of examples to select automatically (overrides the preset).
    examples : list of str, optional
        Use these examples by name instead of the automatic selection.
    backend : str, optional
        Search backend (overrides the preset).
    example_preference : float, optional
        Extra cost per rank of a selected example (overrides the preset).
    vote : {"copy", "mean", "mode"}, optional
        How matches make the map (overrides the preset; ``"mean"`` is the paper's).
    appearance_pyramid : {"gaussian", "laplacian"}, optional
        Plain colours per level (default) or the paper's Laplacian bands
        (overrides the preset).
    edge_support : float, optional
        Share of an edge on a seam within one example that the voted map must show
        for the copy to keep it sharp (overrides the preset; 0 blends every seam).
    complete_features : bool, optional
        Copy whole the examples' small features that the copy cut (overrides the
        preset; see :mod:`imagemap.depth.completion`).
    even_palettes : bool, optional
        Shift a part copied from two examples (a face's skin) into one example's
        colours (overrides the preset; see :mod:`imagemap.depth.palettes`).
    seed : int
        The same seed gives the same bytes.
    quiet : bool
        No progress bar.

    Returns
    -------
    ColorizeResult

    Examples
    --------
    >>> result = colorize(depth, db, preset="fish", m=2, seed=0)  # doctest: +SKIP
    >>> result.rgba.shape  # doctest: +SKIP
    (150, 200, 4)
    """
    examples = check_colorize_arguments(**locals())  # InputError naming the argument; memory
    params = _resolve(
        preset,
        m=m,
        backend=backend,
        example_preference=example_preference,
        vote=vote,
        appearance_pyramid=appearance_pyramid,
        edge_support=edge_support,
        complete_features=complete_features,
        even_palettes=even_palettes,
    )
    depth = validate_depth(depth)
    if len(database) == 0:
        raise InputError("the database has no examples")
    start = time.perf_counter()
    if examples:
        chosen = [database[name] for name in examples]
    else:
        n = params.m
        if n > len(database):
            log.warning("m=%d but the database has %d examples: using all", n, len(database))
            n = len(database)
        chosen = [database[i] for i in select_examples(depth, database, n)]
    log.info("examples: %s", ", ".join(e.name for e in chosen))
    selection_seconds = time.perf_counter() - start

    start = time.perf_counter()
    mask = depth > 0
    levels = pyramid_levels(mask, params.patch_sizes, grow=params.grow_pyramid)
    if levels != params.levels:
        log.info("object size calls for %d pyramid levels (preset: %d)", levels, params.levels)
        params = replace(params, patch_sizes=level_patch_sizes(params.patch_sizes, levels))
    clip = params.detail_clip or None
    outline = bool(params.silhouette_weight)
    # Handed over to the engine, which drops each level once it has packed its bands.
    query = ReleasableLevels(depth_mappings(depth, levels, clip, outline))
    exemplar_levels = [
        ReleasableLevels(example_mappings(e, levels, params.appearance_pyramid, clip, outline))
        for e in chosen
    ]
    pyramid_seconds = time.perf_counter() - start

    engine_params = params.engine_params(
        len(chosen), *context_level_weights(mask, params.patch_sizes, params.wide_context_weight)
    )
    # The features are drawn (final reseed, no example preference) at the finest level
    # whose window spans at least CONTEXT_FRACTION of the object: the finest at the
    # paper's size. A finer window's relief holds no feature to match on (a 7 px window
    # on a 30 px eye), and depth-only matches there would scatter palette patches.
    engine_params = replace(engine_params, feature_level=context_levels(mask, params.patch_sizes))
    result: EngineResult = synthesize(query, exemplar_levels, engine_params, seed=seed, quiet=quiet)
    # The pyramids are done with: freed before the copy finish, whose DCTs and
    # remade examples are the peak of a large map.
    del query, exemplar_levels
    start = time.perf_counter()
    if params.appearance_pyramid == "laplacian":
        ycbcr = collapse_laplacian(result.appearance)
    else:
        ycbcr = result.appearance[0]
    result.appearance = None  # collapsed: not held through the finish
    source = result.source
    if params.vote in ("copy", "mode"):
        # Every pixel copied from the exemplar pixel its windows agree on, the seams
        # blended in the gradient domain into the voted result.
        # Made again rather than kept from the pyramids: full-size arrays held through
        # the synthesis would add to its peak memory, and they cost little to remake.
        exemplars = [_example_ycbcr(example) for example in chosen]
        source = result.copy_source
        result.source = result.copy_source = None  # `source` holds what is still needed
        if params.seam_smoothness > 0:
            source = place_seams(exemplars, source, ycbcr, smoothness=params.seam_smoothness)
        if params.merge_regions:
            source = merge_regions(
                exemplars,
                source,
                ycbcr,
                smoothness=params.seam_smoothness,
                masks=[example.mask for example in chosen],
                keep_detail=params.keep_detail,
            )
        if params.complete_features:
            features = [
                completion.small_features(exemplar, example.mask)
                for exemplar, example in zip(exemplars, chosen, strict=True)
            ]
            source, completed = completion.complete_features(
                exemplars,
                source,
                features,
                mask,
                [example.mask for example in chosen],
                relief=(depth, [example.depth for example in chosen]),
            )
            del features  # label maps: not held through the blend, the finish's peak
            log.info("small features completed: %d", completed)
        # Outside the object the voted map is whatever the windows left there (zero where
        # no window reached: black in YCbCr terms is green); the blend must not pull the
        # object's edge towards it, so the reference there is the copy itself.
        for y0 in range(0, mask.shape[0], _ROWS):  # by rows: no full-size float64 copy
            rows = slice(y0, y0 + _ROWS)
            outside = ~mask[rows] & (source[rows, :, 0] >= 0)
            if outside.any():
                ycbcr[rows][outside] = copy_through(exemplars, source[rows][outside][None])[0]
        edge_reference = None
        if params.even_palettes:
            shift = palettes.even_palettes(
                exemplars, [example.mask for example in chosen], source, mask, seed=seed
            )
            if shift is not None:
                # The edges kept are judged on the colours as copied: a part shifted next
                # to one that is not must not lose its edge.
                edge_reference = ycbcr.copy()
                ycbcr += shift
            del shift
        size = float(np.sqrt(mask.sum()))
        scale = max(params.blend_scale * size, 1.0)
        ycbcr = seamless_copy(
            exemplars,
            source,
            ycbcr,
            scale=scale,
            edge_support=params.edge_support,
            mask=mask,
            edge_reference=edge_reference,
        )
    image = to_rgb(ycbcr)
    image[~mask] = 0.0
    timings = {"selection": selection_seconds, "pyramids": pyramid_seconds, **result.timings}
    timings["collapse"] = time.perf_counter() - start
    return ColorizeResult(
        image=image,
        mask=mask,
        source=source,
        cost=result.cost,
        example_names=[e.name for e in chosen],
        objective=result.objective,
        timings=timings,
        params=params,
    )
