"""The depth front end's bands, pyramid and level plan.

Guide bands per pyramid level: the depth's Gaussian level, its high frequencies
(the Laplacian band of the same level, in units of its own spread inside the
object) and the silhouette (signed distance to the outline), with the depth
continued past the outline. Appearance bands: the Y, Cb and Cr of the image-map
at each level, plain (Gaussian) or as the paper's Laplacian bands. The pyramid has
as many levels as the object's size calls for, and :func:`level_plans` states what
the engine does at each of them.

Examples
--------
>>> mask = np.zeros((150, 200), bool); mask[30:120, 50:150] = True
>>> pyramid_levels(mask, (7, 11, 9))
3
>>> depth = np.where(mask, 0.5, 0.0).astype(np.float32)
>>> [level.guide.shape for level in depth_mappings(depth, levels=2)]
[(150, 200, 3), (75, 100, 3)]
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy import ndimage

from imagemap.core.blend import fill_background, nearest_object_pixels
from imagemap.core.mapping import Mapping
from imagemap.core.params import APPEARANCE_PYRAMIDS, LevelPlan
from imagemap.core.pyramid import (
    gaussian_pyramid,
    laplacian_bands,
    laplacian_pyramid,
    mask_pyramid,
)
from imagemap.depth.config import DepthConfig, Guides, Pyramid
from imagemap.example import Example
from imagemap.io import validate_depth

__all__ = [
    "CROP_SLACK",
    "context_level_weights",
    "crop_levels",
    "context_levels",
    "depth_mappings",
    "example_colours",
    "example_mappings",
    "example_ycbcr",
    "level_patch_sizes",
    "level_plans",
    "pyramid_levels",
    "sized_config",
    "sized_pyramid",
    "to_rgb",
    "to_ycbcr",
]

_PYRAMID = Pyramid()
_GUIDES = Guides()
#: The coarsest level must see the object at least this many windows across (a window
#: larger than the object matches nothing but the silhouette): with windows 7, 11, 9 only
#: objects under 45 px across lose a level (0.75 and 2.5 left 1x fish and busts as they were, #43).
MIN_WINDOWS_ACROSS = 1.25
#: EM iterations at most at the levels finer than the feature level: they refine the layout
#: that level drew (a long EM there wore brows that touch the hair down into it). Only large
#: maps have such levels (none at 1x, where #43's sweep of 1 and 4 changed nothing).
REFINE_ITERATIONS = 2
#: PatchMatch passes per search at those levels (None: ``EngineParams.patchmatch_passes``,
#: 4): their matches start from the feature level's, propagated, and half the passes keep
#: both scan directions. #44 item 5, seed 0 / 1, against 4: 12 fish at 4x macro part
#: transfer 0.8585 / 0.8629 against 0.8624 / 0.8604, fragments for 90 % 48.5 / 46.5 against
#: 50 / 44.5, blur ratio 0.962 / 0.960 against 0.968 / 0.964; 6 busts at 4x 0.834 / 0.845
#: against 0.840 / 0.840, fragments 18 / 15.5 against 16 / 17.5; relief plates / scales /
#: bricks at 320x240 seam F1 0.971 / 0.971 / 0.989 against 0.970 / 0.972 / 0.991 (1 pass:
#: scales 0.966). 1x maps have no such level.
REFINE_PASSES: int | None = 2
#: PatchMatch's random search at those levels starts at this radius (pixels; None: the
#: example's larger side): their matches come from the feature level's, within a few
#: pixels of where they belong, and the far trials (5 of 10 at 512^2) were wasted. #44:
#: the finest level's first search at 512^2, feature distance 190.0k against 192.4k in
#: 0.24 against 0.41 s CPU (8: 192.4k, 32: 191.2k, 64: 192.1k).
REFINE_RADIUS: int | None = 16
#: The feature level's final reseed (:class:`~imagemap.core.params.LevelPlan`): 36 busts
#: drew 91 % of eyes, brows and lips instead of 83 % (0.5 and 0.85 within the seed spread, #43).
FINAL_RESEED = 0.7


def context_levels(
    mask: np.ndarray,
    patch_sizes: tuple[int, ...],
    context_fraction: float = _PYRAMID.context_fraction,
) -> int:
    """How many of the finest levels see the coarser levels' colours: those whose window
    spans less than ``context_fraction`` of the object's size (square root of its area).

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
    return sum(1 for span in spans if span < context_fraction)


def context_level_weights(
    mask: np.ndarray,
    patch_sizes: tuple[int, ...],
    wide: float = 0.0,
    context_fraction: float = _PYRAMID.context_fraction,
) -> tuple[int, tuple[float, ...]]:
    """Which levels see the coarser levels' colours, and how strongly.

    Returns the number of the finest levels with context and a factor per level
    (finest first) on the context band's weight (the Y weight): 1 where a window spans less than
    ``context_fraction`` of the object (its own band holds almost nothing of the
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
    fine = context_levels(mask, patch_sizes, context_fraction)
    n = len(patch_sizes)
    weights = [1.0 if level < fine else float(wide) for level in range(n - 1)] + [0.0]
    count = max((level + 1 for level, w in enumerate(weights) if w > 0), default=0)
    return count, tuple(weights)


def pyramid_levels(
    mask: np.ndarray,
    patch_sizes: tuple[int, ...],
    grow: bool = True,
    add_windows_across: float = _PYRAMID.add_windows_across,
) -> int:
    """How many pyramid levels the object's size calls for.

    The object's size is the square root of its area. A preset's coarsest level
    is dropped while the object, at that level, is less than
    ``MIN_WINDOWS_ACROSS`` windows across (a window larger than the object
    matches nothing but the silhouette); levels are added while the next coarser
    level would still see the object ``add_windows_across`` windows across, so that
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
        while size / 2**levels >= add_windows_across * patch_sizes[-1]:
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


def sized_pyramid(mask: np.ndarray, pyramid: Pyramid) -> Pyramid:
    """``pyramid`` with the windows of as many levels as the object's size calls for.

    Examples
    --------
    >>> big = np.zeros((600, 800), bool); big[100:500, 100:700] = True
    >>> sized_pyramid(big, Pyramid()).patch_sizes
    (7, 7, 7, 11, 9)
    """
    levels = pyramid_levels(
        mask,
        pyramid.patch_sizes,
        grow=pyramid.grow,
        add_windows_across=pyramid.add_windows_across,
    )
    if levels == pyramid.levels:
        return pyramid
    return replace(pyramid, patch_sizes=level_patch_sizes(pyramid.patch_sizes, levels))


def sized_config(config: DepthConfig, mask: np.ndarray) -> DepthConfig:
    """``config`` with its pyramid sized for the object ``mask`` (:func:`sized_pyramid`):
    the first step of every synthesis, before its stages run.

    Examples
    --------
    >>> big = np.zeros((600, 800), bool); big[100:500, 100:700] = True
    >>> sized_config(DepthConfig(), big).pyramid.levels
    5
    """
    return replace(config, pyramid=sized_pyramid(mask, config.pyramid))


def feature_level(mask: np.ndarray, pyramid: Pyramid) -> int:
    """The level whose windows draw the small features: the finest whose window spans at
    least ``context_fraction`` of the object (the finest at the paper's size). A finer
    window's relief holds no feature to match on (a 7 px window on a 30 px eye), and
    depth-only matches there would scatter palette patches."""
    fine = context_levels(mask, pyramid.patch_sizes, pyramid.context_fraction)
    return min(fine, pyramid.levels - 1)


def level_plans(config: DepthConfig, mask: np.ndarray, n_examples: int) -> tuple[LevelPlan, ...]:
    """What the engine does at each level of ``config``'s (sized) pyramid, finest first.

    - The feature level (:func:`feature_level`) draws the small features: the final
      reseed runs after its EM, and it takes a feature from whichever example draws
      it (no example preference there or finer, unless ``preference_at_finest``);
    - the coarser levels prefer the nearest examples (``example_preference`` per
      rank), so that each region comes from one example where it fits nearly as well;
    - the levels finer than the feature level refine its layout
      (at most ``REFINE_ITERATIONS``);
    - the levels whose windows span little of the object see the coarser levels'
      luminance as context, the others but the coarsest weakly
      (:func:`context_level_weights`).

    Examples
    --------
    >>> mask = np.zeros((150, 200), bool); mask[30:120, 50:150] = True
    >>> plans = level_plans(DepthConfig(), mask, n_examples=2)
    >>> [(p.patch_size, p.exemplar_costs, p.final_reseed) for p in plans]
    [(7, (0.0, 30.0), 0.7), (11, (0.0, 30.0), 0.0), (9, (0.0, 30.0), 0.0)]
    >>> paper = DepthConfig().replace_fields(example_preference=0.3, preference_at_finest=False)
    >>> [plan.exemplar_costs for plan in level_plans(paper, mask, n_examples=2)]
    [(), (0.0, 0.3), (0.0, 0.3)]
    """
    pyramid, guides, matching = config.pyramid, config.guides, config.matching
    n_levels = pyramid.levels
    feature = feature_level(mask, pyramid)
    costs = tuple(matching.example_preference * rank for rank in range(n_examples))
    count, factors = context_level_weights(
        mask, pyramid.patch_sizes, guides.wide_context_weight, pyramid.context_fraction
    )
    with_context = count > 0
    # The mean vote's map is the EM's own vote: matches changed after it would describe
    # (source, provenance) a map that was not made from them.
    final_reseed = FINAL_RESEED if config.finish.vote != "mean" else 0.0
    size = float(np.sqrt(mask.sum()))
    plans = []
    for level, k in enumerate(pyramid.patch_sizes):
        preferred = matching.example_preference and (
            level > feature or n_levels == 1 or matching.preference_at_finest
        )
        context: tuple[float, ...] = ()
        if with_context and factors[level] > 0 and level < n_levels - 1:
            context = (factors[level] * matching.luma_weight, 0.0, 0.0)
        plans.append(
            LevelPlan(
                patch_size=k,
                max_iterations=(
                    min(matching.max_iterations, REFINE_ITERATIONS)
                    if level < feature
                    else matching.max_iterations
                ),
                exemplar_costs=costs if preferred else (),
                context_weights=context,
                guide_reseed=matching.guide_reseed,
                final_reseed=final_reseed if level == feature else 0.0,
                position_weight=(
                    guides.registered_position_weight
                    * max(1.0, size / 2**level / guides.registered_reference_size)
                    * (guides.registered_feature_factor if level <= feature else 1.0)
                    if guides.registration
                    else None
                ),
                final_reseed_any_exemplar=bool(guides.registration and guides.free_final_reseed),
                patchmatch_passes=REFINE_PASSES if level < feature else None,
                search_radius=REFINE_RADIUS if level < feature else None,
            )
        )
    return tuple(plans)


def _interior_scale(detail: np.ndarray, mask: np.ndarray, percentile: float) -> float:
    """The detail band's unit: a high percentile of its magnitude inside the object."""
    inner = ndimage.binary_erosion(mask, iterations=2) if mask.any() else mask
    values = detail[inner] if inner.sum() >= 16 else detail[mask] if mask.any() else detail
    scale = float(np.percentile(np.abs(values), percentile)) if values.size else 0.0
    return scale if scale > 0 else max(float(np.abs(detail).max()), 1e-12)


def _extend_depth(
    depth: np.ndarray, mask: np.ndarray, sigma: float, nearest: np.ndarray | None = None
) -> np.ndarray:
    """The depth continued past the outline: nearest object depth, smoothed outside
    (``nearest``: the mask's :func:`~imagemap.core.blend.nearest_object_pixels`, if made).

    Windows at the outline then compare relief with relief; the outline itself
    is the silhouette band's job.
    """
    outside = ndimage.gaussian_filter(fill_background(depth, mask, nearest), sigma)
    return np.where(mask, depth, outside).astype(np.float32)


def silhouette_band(mask: np.ndarray, saturation: float = _GUIDES.silhouette_range) -> np.ndarray:
    """Signed distance to the outline (positive inside), in units of ``saturation``
    pixels and clipped to [-1, 1].

    Examples
    --------
    >>> mask = np.zeros((1, 7), bool); mask[0, 3:] = True
    >>> silhouette_band(mask).round(2).tolist()
    [[-1.0, -1.0, -0.5, 0.5, 1.0, 1.0, 1.0]]
    """
    mask = np.asarray(mask, bool)
    reach = int(np.ceil(saturation))
    # Farther than ``reach`` from the object the band is -1 (no object pixel within the
    # saturation). It is made on the object's box and ``reach`` + 1 pixels around it,
    # which hold every object pixel, every pixel within reach of one and its neighbours
    # within reach (the same values), -1 elsewhere: an object is often a third of its
    # frame.
    rows, columns = np.flatnonzero(mask.any(1)), np.flatnonzero(mask.any(0))
    if not len(rows) or not saturation > 0:  # (a saturation of 0 divides 0 by 0: NaN)
        return _silhouette(mask, saturation, reach)
    box = (
        slice(max(rows[0] - reach - 1, 0), rows[-1] + reach + 2),
        slice(max(columns[0] - reach - 1, 0), columns[-1] + reach + 2),
    )
    out = np.full(mask.shape, -1.0, np.float32)
    out[box] = _silhouette(mask[box], saturation, reach)
    return out


def _silhouette(mask: np.ndarray, saturation: float, reach: int) -> np.ndarray:
    """:func:`silhouette_band` of ``mask`` as a whole (``reach``: the saturation rounded
    up)."""
    offsets = [
        (dy, dx, float(np.sqrt(dy * dy + dx * dx)))
        for dy in range(-reach, reach + 1)
        for dx in range(-reach, reach + 1)
        if 0 < dy * dy + dx * dx < saturation * saturation
    ]
    if len(offsets) > _SILHOUETTE_OFFSETS:
        inside = ndimage.distance_transform_edt(mask)
        outside = ndimage.distance_transform_edt(~mask)
    else:
        # Distances past ``saturation`` are clipped away, so only the offsets nearer than
        # it are looked at: a few shifted comparisons instead of two full distance
        # transforms (the same values).
        height, width = mask.shape
        inside = np.zeros(mask.shape)
        outside = np.zeros(mask.shape)
        inside[mask] = outside[~mask] = saturation
        for dy, dx, distance in offsets:
            here = (slice(max(-dy, 0), height - max(dy, 0)), slice(max(-dx, 0), width - max(dx, 0)))
            there = (slice(max(dy, 0), height + min(dy, 0)), slice(max(dx, 0), width + min(dx, 0)))
            at, near = mask[here], mask[there]
            np.minimum(inside[here], distance, out=inside[here], where=at & ~near)
            np.minimum(outside[here], distance, out=outside[here], where=~at & near)
    signed = (inside - outside) / saturation
    return np.clip(signed, -1.0, 1.0).astype(np.float32)


#: Above this many offsets nearer than the silhouette's saturation, two distance
#: transforms are faster than one shifted comparison per offset (measured at 1024^2:
#: a transform pair about 0.25 s, an offset about 4 ms); either gives the same band.
_SILHOUETTE_OFFSETS = 48


def _depth_guides(
    depth: np.ndarray,
    masks: list[np.ndarray],
    guides: Guides,
    nearest: np.ndarray | None = None,
) -> list[np.ndarray]:
    """Per level of ``masks`` (the object's mask pyramid): (H_l, W_l, B) depth Gaussian
    level, its Laplacian (detail) band and, with a silhouette weight, the silhouette band
    (the depth then extended past the outline; ``nearest``: the finest mask's
    :func:`~imagemap.core.blend.nearest_object_pixels`, if made)."""
    levels = len(masks)
    silhouette = bool(guides.silhouette_weight)
    clip = guides.detail_clip or None
    if silhouette:
        depth = _extend_depth(depth, masks[0], guides.extension_sigma, nearest)
    # One level more, so that even the coarsest level has a true band-pass detail band
    # (the Laplacian pyramid's bands of the one Gaussian pyramid: smoothed once).
    gaussian = gaussian_pyramid(depth, levels + 1)
    detail = laplacian_bands(gaussian)
    gaussian = gaussian[:levels]
    if clip:
        scaled = []
        for d, m in zip(detail, masks, strict=True):
            unit = _interior_scale(d, m, guides.detail_percentile)
            scaled.append((clip * unit) * np.tanh(d / (clip * unit)))
        detail = scaled
    bands = [[g, d] for g, d in zip(gaussian, detail, strict=True)]
    if silhouette:
        for level_bands, m in zip(bands, masks, strict=True):
            level_bands.append(silhouette_band(m, guides.silhouette_range))
    return [np.stack(level_bands, axis=-1) for level_bands in bands]


def depth_mappings(
    depth: np.ndarray,
    levels: int = 3,
    guides: Guides = _GUIDES,
    positions: list[np.ndarray] | None = None,
    position_scales: list[np.ndarray | None] | None = None,
    nearest: np.ndarray | None = None,
) -> list[Mapping]:
    """The query's pyramid of mappings (guide bands and mask) for a depth map;
    ``positions`` (per level, (H_l, W_l, 2)) replace the engine's relative position,
    ``position_scales`` (per level, (H_l, W_l)) are the position term's factors;
    ``nearest``: the object's :func:`~imagemap.core.blend.nearest_object_pixels`, if made."""
    depth = validate_depth(depth)
    masks = mask_pyramid(depth > 0, levels)
    level_positions: list[np.ndarray | None] = list(positions) if positions else [None] * levels
    scales: list[np.ndarray | None] = list(position_scales) if position_scales else [None] * levels
    return [
        Mapping(
            guide=guide,
            mask=mask if mask.any() else None,
            position=position,
            position_scale=scale,
        )
        for guide, mask, position, scale in zip(
            _depth_guides(depth, masks, guides, nearest),
            masks,
            level_positions,
            scales,
            strict=True,
        )
    ]


_ROWS = 256  # rows per block of the colour conversions
#: skimage.color's BT.601 matrices: ``ycbcr_from_rgb``, and ``rgb_from_ycbcr``, its inverse as
#: ``scipy.linalg.inv`` makes it on Intel CPUs (NumPy's inverse differs in the last bits),
#: held here so that the maps' bytes do not follow the CPU's LAPACK kernels (on AMD EPYC
#: skimage's own inverse differs by 5e-20 in two near-zero entries; the conversions' float32
#: values are the same: a test checks them against skimage's). The conversions then need no
#: ``skimage.color``, whose import (with ``skimage.util``) is a fresh synthesis's only use.
_YCBCR_FROM_RGB = np.array(
    [[65.481, 128.553, 24.966], [-37.797, -74.203, 112.0], [112.0, -93.786, -18.214]]
)
_RGB_FROM_YCBCR = np.array(
    [
        [0.004566210045662101, 1.1808799898470919e-09, 0.006258928969943936],
        [0.004566210045662101, -0.0015363236860449021, -0.003188110949655707],
        [0.004566210045662101, 0.007910716233554741, 1.1977497040200258e-08],
    ]
)


def _rgb2ycbcr(rgb: np.ndarray) -> np.ndarray:
    """``skimage.color.rgb2ycbcr``: for float32 and float64 pictures its operations, in its
    order (the same values); other types by skimage itself (it rescales integers)."""
    if rgb.dtype not in (np.float32, np.float64):
        from skimage import color  # deferred: start-up (only pictures that are not floats)

        return color.rgb2ycbcr(rgb)
    arr = rgb @ _YCBCR_FROM_RGB.T.astype(rgb.dtype)
    arr[..., 0] += 16
    arr[..., 1] += 128
    arr[..., 2] += 128
    return arr


def to_ycbcr(rgb: np.ndarray) -> np.ndarray:
    """RGB in [0, 1] to YCbCr scaled to [0, 1] (ITU-R BT.601, as skimage).

    Examples
    --------
    >>> [round(float(v), 3) for v in to_ycbcr(np.ones((1, 1, 3), np.float32))[0, 0]]
    [0.922, 0.502, 0.502]
    """
    # In blocks of rows: skimage works in float64 (several full-size copies at 4096^2).
    out = np.empty(rgb.shape, dtype=np.float32)
    for y in range(0, rgb.shape[0], _ROWS):
        out[y : y + _ROWS] = _rgb2ycbcr(rgb[y : y + _ROWS]) / 255.0
    return out


def to_rgb(ycbcr: np.ndarray) -> np.ndarray:
    """Inverse of :func:`to_ycbcr`, clipped to [0, 1] (``skimage.color.ycbcr2rgb``'s
    operations, in its order).

    Examples
    --------
    >>> rgb = np.array([[[0.2, 0.5, 0.9]]], np.float32)
    >>> bool(np.allclose(to_rgb(to_ycbcr(rgb)), rgb, atol=1e-5))
    True
    """
    # In blocks of rows, as to_ycbcr: skimage's float64 copies of a 4096^2 map were
    # several 400 MB arrays at once, at the end of the pipeline.
    out = np.empty(ycbcr.shape, dtype=np.float32)
    for y in range(0, ycbcr.shape[0], _ROWS):
        block = ycbcr[y : y + _ROWS].astype(np.float64) * 255.0
        block[..., 0] -= 16
        block[..., 1] -= 128
        block[..., 2] -= 128
        out[y : y + _ROWS] = np.clip(block @ _RGB_FROM_YCBCR.T.astype(np.float64), 0.0, 1.0)
    return out


def example_colours(
    example: Example, nearest: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray | None]:
    """An example's :func:`example_ycbcr` and its mask's nearest object pixels
    (:func:`~imagemap.core.blend.nearest_object_pixels`; None for a mask that is all or
    nothing): the colours' fill and the depth's continuation past the outline read the
    same nearest pixels, one distance transform for both (``nearest``: those pixels,
    if made already)."""
    mask = example.mask
    if nearest is None and mask.any() and not mask.all():
        nearest = nearest_object_pixels(mask)
    return example_ycbcr(example, nearest), nearest


def example_ycbcr(example: Example, nearest: np.ndarray | None = None) -> np.ndarray:
    """An example's image-map in YCbCr, the background filled with the nearest object colour
    (``nearest``: its mask's :func:`~imagemap.core.blend.nearest_object_pixels`, if made)."""
    # The image read from disk is not left cached on the example: the synthesis keeps
    # only its colour bands, and the finish reads it again (a full-size float32 image
    # per example less through the synthesis).
    cache = getattr(example, "__dict__", {})
    cached = "image" in cache
    image = example.image
    if not cached and "image" in cache:  # filled just now (a cached_property): emptied
        del cache["image"]
    return to_ycbcr(fill_background(image, example.mask, nearest))


#: Pixels of a level kept around its object past the engine's reach (its dilated mask
#: and windows: twice the largest window radius) when an example's mappings are cropped:
#: room for the coarser level's colours expanded onto the crop (one coarse pixel) and
#: to spare. The engine checks that its windows stay inside.
CROP_SLACK = 8


def crop_levels(mappings: list[Mapping], radius: int) -> list[Mapping]:
    """An exemplar's pyramid cut to its object: each level the box of its mask and
    ``2 * radius + CROP_SLACK`` pixels around it (``radius``: the largest window radius
    the engine uses), aligned from level to level (a level's origin twice the coarser
    one's), in copies (the whole frames are not held). The engine gives the same bytes
    (:class:`~imagemap.core.mapping.Mapping`'s ``origin``). Levels without a mask, or
    a crop that would be the whole frame, are left as they are.

    Examples
    --------
    >>> mask = np.zeros((64, 80), bool); mask[20:30, 40:50] = True
    >>> depth = np.where(mask, 0.5, 0.0).astype(np.float32)
    >>> cropped = crop_levels(depth_mappings(depth, levels=2), radius=2)
    >>> [(level.origin, level.shape, level.frame) for level in cropped]
    [((0, 16), (54, 58), (64, 80)), ((0, 8), (27, 29), (32, 40))]
    """
    if any(level.mask is None for level in mappings):
        return mappings
    n = len(mappings)
    align = 2 ** (n - 1)
    top, left, bottom, right = np.inf, np.inf, -np.inf, -np.inf
    for level, mapping in enumerate(mappings):
        assert mapping.mask is not None
        inside_rows = np.flatnonzero(mapping.mask.any(axis=1))
        inside_cols = np.flatnonzero(mapping.mask.any(axis=0))
        margin = 2 * radius + CROP_SLACK
        scale = 2**level  # the box and its margin in the finest level's pixels
        top = min(top, (inside_rows[0] - margin) * scale)
        left = min(left, (inside_cols[0] - margin) * scale)
        bottom = max(bottom, (inside_rows[-1] + 1 + margin) * scale)
        right = max(right, (inside_cols[-1] + 1 + margin) * scale)
    height, width = mappings[0].shape
    y0, x0 = int(max(top, 0)) // align * align, int(max(left, 0)) // align * align
    y1, x1 = int(min(bottom, height)), int(min(right, width))
    if (y0, x0, y1, x1) == (0, 0, height, width):
        return mappings
    cropped = []
    for level, mapping in enumerate(mappings):
        scale = 2**level
        oy, ox = y0 // scale, x0 // scale
        rows = slice(oy, min(-(-y1 // scale), mapping.shape[0]))
        cols = slice(ox, min(-(-x1 // scale), mapping.shape[1]))

        def cut(array, rows=rows, cols=cols):
            return None if array is None else array[rows, cols].copy()

        cropped.append(
            Mapping(
                guide=cut(mapping.guide),
                appearance=cut(mapping.appearance),
                mask=cut(mapping.mask),
                position=cut(mapping.position),
                position_scale=cut(mapping.position_scale),
                origin=(oy, ox),
                frame_shape=mapping.frame,
            )
        )
    return cropped


def example_mappings(
    example: Example,
    levels: int = 3,
    appearance_pyramid: str = "gaussian",
    guides: Guides = _GUIDES,
    positions: list[np.ndarray] | None = None,
    crop_radius: int | None = None,
    *,
    colours: tuple[np.ndarray, np.ndarray | None] | None = None,
) -> list[Mapping]:
    """An example's pyramid of mappings: depth bands, YCbCr (Gaussian or Laplacian) levels,
    mask, and (``positions``, per level) where its pixels lie on the query; with
    ``crop_radius`` (the engine's largest window radius) cut to the object
    (:func:`crop_levels`). ``colours``: its :func:`example_colours`, if made."""
    if appearance_pyramid not in APPEARANCE_PYRAMIDS:
        raise ValueError(f"appearance_pyramid must be one of {APPEARANCE_PYRAMIDS}")
    mask = example.mask
    ycbcr, nearest = example_colours(example) if colours is None else colours
    if appearance_pyramid == "laplacian":
        appearance = laplacian_pyramid(ycbcr, levels)
    else:
        appearance = gaussian_pyramid(ycbcr, levels)
    masks = mask_pyramid(mask, levels)
    level_positions: list[np.ndarray | None] = list(positions) if positions else [None] * levels
    mappings = [
        Mapping(
            guide=guide,
            appearance=bands,
            mask=level_mask if level_mask.any() else None,
            position=position,
        )
        for guide, bands, level_mask, position in zip(
            _depth_guides(example.depth, masks, guides, nearest),
            appearance,
            masks,
            level_positions,
            strict=True,
        )
    ]
    del appearance, masks, level_positions, nearest
    return mappings if crop_radius is None else crop_levels(mappings, crop_radius)
