"""The depth front end's configuration: one frozen, nested :class:`DepthConfig`.

One module for one job: the settings, their groups, presets and the options that set them.

Every setting of a depth-map colorization is a field here, grouped by the part of
the pipeline that reads it (:mod:`imagemap.depth.pipeline`): which examples
(:class:`Selection`), how many pyramid levels (:class:`Pyramid`), how each example is
warped onto the query (:class:`Registration`), the depth's guide bands
(:class:`Guides`), the engine's matching (:class:`Matching`), how the matches make the
map (:class:`Finish`) and which small features the copy completes
(:class:`Completion`). Each field's comment says what it is for and where its value
comes from; ``docs/presets.md`` has the measurements.

Class presets are configurations (:data:`PRESETS`), and the options a user may set
from the command line, a batch or the Python API are declared once, in
:data:`OPTIONS` (:mod:`imagemap.depth.options`, re-exported here): the CLI's flags,
:class:`imagemap.batch.BatchOptions` and :func:`imagemap.colorize`'s keywords are all
made from it.

This module imports nothing heavy; the command line builds its parser from
:mod:`imagemap.depth.options` alone (making this module's dataclasses costs about 15 ms
of a start).

Examples
--------
>>> config = resolve_config("fish", vote="mean")
>>> config.finish.vote, config.guides.position_weight, config.selection.m
('mean', 0.5, 2)
>>> paper = resolve_config("busts", finish="paper")
>>> paper.finish.vote, paper.matching.appearance_pyramid, paper.finish.complete_features
('mean', 'laplacian', False)
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, fields, replace
from typing import Any

from imagemap.core.choices import APPEARANCE_PYRAMIDS, BACKENDS, VOTES
from imagemap.depth.options import FINISHES, OPTION_NAMES, OPTIONS, Option
from imagemap.errors import InputError
from imagemap.validate import check_float, check_settings, setting

__all__ = [
    "FINISHES",
    "METHODS",
    "OPTIONS",
    "PRESETS",
    "VOTES",
    "Completion",
    "DepthConfig",
    "Finish",
    "Guides",
    "Matching",
    "Option",
    "Pyramid",
    "Registration",
    "Selection",
    "apply_options",
    "resolve_config",
]


@dataclass(frozen=True)
class Selection:
    """Which examples the synthesis uses, and where the query lies against them (the
    ``select`` and ``pose`` stages, :mod:`imagemap.depth.pose`)."""

    #: Examples chosen automatically, nearest in shape (paper, Sec. 2.3; Table 1: 1 for
    #: humans, 2 for busts and fish).
    #: Swept (#43; 12 fish/busts at 1x, seed 0, macro part transfer; the default 0.814/0.776, seed
    #: to seed 0.004/0.014): 1 -> 0.810/0.764 (a bust's feature not drawn); 3 -> 0.816/0.778, one
    #: more example registered and searched.
    #: Relief plates/scales at 320x240, seam/rim F1 (the default 0.970/0.972): 1 -> 0.968/0.968
    #: (their databases hold 2).
    m: int = setting(2, kind="int", minimum=1)
    #: Try every example mirrored too (the fit decides): a fish facing the other way
    #: than its examples is made from them mirrored. Off for a class that is not
    #: mirror-symmetric (writing on a label, a heart on the left).
    #: Measured (#42, docs/shape.md): a held-out fish mirrored gave the mirrored map (equivariance
    #: 1.8 ΔE00) where without it the map kept the examples' side (19).
    mirror: bool = setting(True, kind="bool")
    #: A turn up to this many degrees and a scale within this factor of the first
    #: example's are left to the registration's warp (which absorbs them): the query is
    #: then only moved by whole pixels (and mirrored), not resampled onto the example's
    #: grid, and its own pixels, part borders and small features stay where they are (12
    #: fish: macro part transfer 0.785 resampled, 0.80 not; the generated objects lie
    #: within 5 degrees and 0.85-1.2 of each other). Beyond, the pose is undone exactly.
    pose_turn_tolerance: float = setting(10.0, minimum=0.0, maximum=90.0)
    #: Swept (#43; 12 fish/busts at 1x, seed 0, macro part transfer; the default 0.816/0.778):
    #: 1.1 -> 0.817/0.778 (fish fragments 16.5 against 20.5), 1.5 -> the default's figures.
    pose_scale_tolerance: float = setting(1.25, minimum=1.0)

    def __post_init__(self) -> None:
        check_settings(self)


@dataclass(frozen=True)
class Pyramid:
    """How many pyramid levels, and their windows."""

    #: Window width per level, fine to coarse, for the paper's 200x150 objects (Table 1).
    #: Tried (docs/presets.md): a finest window of 5 was a little better on fish and humans, but
    #: busts lost features (88 % drawn, 67 % of busts complete).
    patch_sizes: tuple[int, ...] = setting((7, 11, 9), kind="odd_widths")
    #: Add finer levels for large objects so that the coarsest level sees the object as
    #: the paper's does at 200x150; False keeps the preset's levels (still dropping
    #: levels for small objects).
    #: Swept (#43, seed 0; macro part transfer; against the default in the same run): False -> 6
    #: busts at 4x 0.873 against 0.840 (every feature drawn, 21.5 against 16 fragments for 90 %;
    #: hair and checks more whole, looked at), 6 fish at 4x 0.870 against 0.862; the 2048x1536 fish
    #: 47 against 57 fragments (its gill bar jogs at the top); but the relief tasks at 768x576 lose
    #: seam F1 (plates 0.936 against 0.951, scales 0.943 against 0.952; bricks and 320x240 the
    #: same): a lead for more seeds, not yet a default.
    grow: bool = setting(True, kind="bool")
    #: A level is added while the next coarser one would still see the object this many
    #: windows across (the paper's objects are 2 to 3.5 windows across at its coarsest
    #: level; 3.5 left 4x busts with hair over the brows, docs/presets.md).
    #: Swept (#43; 6 busts at 4x, seed 0, macro part transfer; the default 0.840, every feature
    #: drawn, 16 fragments for 90 %): 2.5 -> 0.841, 18 fragments.
    add_windows_across: float = setting(3.0, minimum=0.0)
    #: A level whose window spans less than this fraction of the object's size (square
    #: root of its area) sees the coarser levels' colours as context, and the finest level
    #: that spans more draws the small features (at 200x150 the finest window spans
    #: 0.05-0.1: none; at 800x600 the two finest levels of a bust).
    #: Swept (#43; 6 busts at 4x, seed 0, macro part transfer; the default 0.840, every feature
    #: drawn, 16 fragments for 90 %): 0.1 -> 0.820, a bust with a feature not drawn (5 of 6 with
    #: every one).
    context_fraction: float = setting(0.05, minimum=0.0)
    #: The largest object (square root of its area, pixels) the engine searches at: a
    #: larger query and its examples are block-averaged by the smallest power of two that
    #: brings the query's object to this size or less, the engine and the seams run
    #: there, and every pixel is copied at full size from the same sub-position of its
    #: source's block (:func:`imagemap.depth.pipeline.fine_source`), then blended at full
    #: size. A 4096^2 map then has the layout of copies of a 1024^2 map by construction
    #: (#44 item 5: 122 fragments for 90 % against 71, the eye's pupil lumpy). 640 keeps
    #: the 1024^2 fish (object 431 px), the 4x evaluation (busts up to 503 px) and the relief
    #: tasks at 768x576 (459-485 px) as they were, with a quarter to spare; the 2048^2 and
    #: 4096^2 fish (862, 1724 px) are averaged by 2 and 4. 0: no cap.
    search_size: float = setting(640.0, minimum=0.0)

    def __post_init__(self) -> None:
        check_settings(self)

    @property
    def levels(self) -> int:
        return len(self.patch_sizes)


@dataclass(frozen=True)
class Registration:
    """How each example is warped onto the query (:mod:`imagemap.depth.register`): an
    affine map from the objects' moments composed with a cubic B-spline free-form
    deformation, fitted by Levenberg-Marquardt to a guide image of each object. Whether
    the ``register`` stage runs at all, and how strongly the engine holds the registered
    positions, are :class:`Guides` settings (``registration``,
    ``registered_position_weight``). The fit's fields were set when it was written
    (9718736, 16d4e17) and swept in #43: each comment's figures are the macro part
    transfer of 12 generated fish and busts at 1x and the seam F1 of #42's relief plates
    at 320x240, seed 0 unless said. The fit's iterations, its pixels and the outline's
    clip made no measurable difference: constants of :mod:`imagemap.depth.register`."""

    #: The working resolution: the object is about this many pixels across (square root
    #: of its area) while the warp is fitted. A smooth warp of a whole object needs no
    #: more, and a 4x map costs what a 1x one does (0.05-0.2 s per pair). Registering at
    #: 128 px with a 10-point grid did not bring the examples' eyes into place either
    #: (4x fish, docs/presets.md).
    #: Swept (#43; 12 fish/busts at 1x, seed 0, macro part transfer; the default 0.814/0.776, seed
    #: to seed 0.004/0.014): 32 -> 0.815/0.772; 128 -> 0.814/0.774 (fragments 21.5/9.5).
    #: Relief plates/scales at 320x240, seam/rim F1 (the default 0.970/0.972): 32 -> 0.971/0.974,
    #: 128 -> 0.963/0.968.
    work_size: float = setting(64.0, minimum=1.0)
    #: Control points per side of the B-spline grids, coarse to fine (over the query
    #: object's box): 4 is nearly affine, 5 bends a body; a third grid of 7 (the default
    #: until #43's sweep) bent fins apart and lost fish 0.008 on every seed.
    #: Swept with grid_smoothing (12 fish/busts' macro part transfer, seeds 0-2; relief plates' seam
    #: F1 at 320x240): (4, 5) with (2, 1) -> 0.816, 0.816, 0.814/0.778, 0.783, 0.781, F1 0.955,
    #: 0.953, 0.949; 4x fish 0.868, 0.865, 4x busts 0.835 (every feature drawn), shells 0.864,
    #: humans 0.864; (4, 5, 7) -> 0.806, 0.810, 0.807/0.775, 0.789, 0.781, F1 0.956, 0.953, 0.953;
    #: 4x fish 0.861, 0.863, 4x busts 0.836 (5 of 6 with every feature), shells 0.864, humans
    #: 0.868; (4, 5, 7, 10) with 0.25 added, seed 0 -> 0.810/0.773, F1 0.955 (seed to seed at the
    #: default: fish 0.004, busts 0.014, F1 0.003).
    control_grids: tuple[int, ...] = (4, 5)
    #: Gaussian smoothing (working pixels) of the guide images per grid: a wide capture
    #: range first, the outline's detail last.
    grid_smoothing: tuple[float, ...] = (2.0, 1.0)
    #: Weight of the control points' squared displacement against the mean squared guide
    #: difference: keeps the warp smooth where the guide says nothing (inside a flat body).
    #: Swept (as control_grids): 1e-3 -> 0.803/0.765, 0.957; 1e-2 -> 0.806/0.775, 0.956; 1e-1 ->
    #: 0.811/0.771, 0.957 (seed to seed at the default, seeds 0-2: fish 0.004, busts 0.014, F1
    #: 0.003).
    stiffness: float = setting(1e-2, minimum=0.0)
    #: Weight of the relief's detail in the registration's guide image
    #: (:func:`imagemap.depth.register.registration_guide`): eyes, lips and brow ridges
    #: pull the warp into place (12 busts' macro part transfer 0.779 -> 0.789 at 0.5).
    registration_relief: float = setting(0.5, minimum=0.0)
    #: The relief's detail is the relative depth less its Gaussian smoothing over this
    #: fraction of the object's size (square root of its area), in units of its 95th
    #: percentile inside the object: a feature's bulge, not the body's curvature.
    #: Swept (as control_grids, seed 0; it also sets the relief's scale for relief_disagreement and
    #: the seams): 0.015 -> 0.807/0.777, F1 0.971 (seeds 1-4: 0.964, 0.951, 0.962, 0.962), shells
    #: 0.879, humans 0.862, more fragments (plates 72-83, shells 88, humans 26); 0.03 ->
    #: 0.806/0.775, F1 0.956 (0.953, 0.953, 0.957, 0.954), shells 0.864, humans 0.868 (fragments
    #: 57-58, 67, 21); 0.06 -> 0.790/0.780, F1 0.925, a fish's eye in 12 not drawn (seed to seed at
    #: the default: fish 0.004, busts 0.014, F1 0.004, shells 0.003, humans 0.003).
    relief_detail_scale: float = setting(0.03, minimum=0.0)
    #: The registration's detail works with the object about this many pixels across: the
    #: guide images (made from block averages, never at full size: at 2048x1536 the
    #: full-size guides, distance transforms and smoothing of 3 million pixels four per
    #: pair, took 5.0 of the registration's 5.2 s), the registered positions (the inverse
    #: warp on a grid of about this many points along the example's longer side, every
    #: 4th pixel at least, interpolated: the warp is smooth over its 4-7 control
    #: intervals; a 4-pixel grid took 4.1 s for two examples at 2048x1536) and the relief's
    #: disagreement (a groove of 1 % of the object is still 2-3 pixels wide). 4 times the
    #: working size: maps up to 4x the default size are unchanged by it.
    detail_size: float = setting(256.0, minimum=16.0)

    def __post_init__(self) -> None:
        check_settings(self)
        # The grids and their smoothing go together: checked as a pair.
        if (
            not isinstance(self.control_grids, tuple)
            or not self.control_grids
            or any(
                not isinstance(n, int) or isinstance(n, bool) or n < 4 for n in self.control_grids
            )
            or len(self.grid_smoothing) != len(self.control_grids)
        ):
            raise InputError(
                f"control_grids: integers of at least 4 (a cubic B-spline's support), one "
                f"grid_smoothing each; got {self.control_grids} and {self.grid_smoothing}"
            )
        for sigma in self.grid_smoothing:
            check_float("grid_smoothing", sigma, minimum=0.0)


@dataclass(frozen=True)
class Guides:
    """The depth's guide bands and their weights (paper, Table 1, restated per band
    standard deviation so that depth in metres, millimetres or [0, 1] gives one result)."""

    #: Weight of the depth's Gaussian level.
    #: Swept (#43; 12 fish/busts at 1x, seed 0, macro part transfer; the default 0.814/0.776, seed
    #: to seed 0.004/0.014): 0.5 -> 0.814/0.773 (fragments for 90 % 23.5/9 against 20.5/8.5); 2 ->
    #: 0.804/0.755, a fish's and a bust's feature not drawn.
    #: Relief plates/scales at 320x240, seam/rim F1 (the default 0.970/0.972): 0.5 -> 0.975/0.971, 2
    #: -> 0.957/0.971.
    depth_weight: float = setting(1.0, minimum=0.0)
    #: Weight of the depth's detail (Laplacian) band.
    #: Swept (#43; 12 fish/busts at 1x, seed 0, macro part transfer; the default 0.814/0.776, seed
    #: to seed 0.004/0.014): 1 -> 0.808/0.758, a fish's eye not drawn; 4 -> 0.802/0.769, busts'
    #: features 93 %, fragments 26.5/10.
    #: Relief plates/scales at 320x240, seam/rim F1 (the default 0.970/0.972): 1 -> 0.843/0.866, 4
    #: -> 0.983/0.975 (the relief's gain is the evaluation's loss).
    depth_detail_weight: float = setting(2.0, minimum=0.0)
    #: The detail band in units of its robust spread inside the object, soft-clipped at
    #: this many units (0: raw band): without it the silhouette's jump sets the band's
    #: scale and interior relief (sockets, lips, an eye's bulge) hardly counts.
    #: Swept (#43; 12 fish/busts at 1x, seed 0, macro part transfer; the default 0.816/0.778):
    #: 1.5 -> 0.818/0.781 (a bust's feature lost), 6 -> 0.812/0.767.
    detail_clip: float = setting(3.0, minimum=0.0)
    #: Percentile of |detail| inside the object taken as its unit: the relief that marks
    #: features, not the body's flat stretches, whose tiny values a median would blow up.
    #: Swept (#43; 12 fish/busts at 1x, seed 0, macro part transfer; the default 0.816/0.778):
    #: 90 -> 0.815/0.770, 99 -> 0.804/0.769 (a fish's feature in 12 lost).
    detail_percentile: float = setting(95.0, minimum=0.0, maximum=100.0)
    #: Weight of the silhouette band (signed distance to the outline); with it the depth
    #: is continued past the outline, so an eye 3 px from the outline matches the
    #: examples' eyes, not their outlines; 0 keeps the paper's bands.
    #: Swept (#43; 12 fish/busts at 1x, seed 0, macro part transfer; the default 0.814/0.776, seed
    #: to seed 0.004/0.014): 0.25 -> 0.814/0.779 (fragments 23/10.5); 1 -> 0.815/0.772: within the
    #: spread; it is kept for the eyes beside the outline (docs/presets.md).
    #: Relief plates/scales at 320x240, seam/rim F1 (the default 0.970/0.972): 0.25 -> 0.971/0.971,
    #: 1 -> 0.962/0.968.
    silhouette_weight: float = setting(0.5, minimum=0.0)
    #: The silhouette band saturates this many pixels of each level from the outline: it
    #: says "edge here" to a window, not how deep inside it is.
    #: Swept (#43; 12 fish/busts at 1x, seed 0, macro part transfer; the default 0.816/0.778):
    #: 1 -> 0.678/0.690 (half the fish's features lost), 4 -> 0.815/0.779 (24/9.5 fragments
    #: for 90 % against 20.5/8.5).
    silhouette_range: float = setting(2.0, minimum=0.0)
    #: Smoothing (pixels) of the depth continued past the outline.
    #: Swept (#43; 12 fish/busts at 1x, seed 0, macro part transfer; the default 0.816/0.778):
    #: 1 -> 0.815/0.774, 4 -> 0.818/0.769.
    extension_sigma: float = setting(2.0, minimum=0.0)
    #: Weight of the position relative to the object's centroid, per RMS radius of the
    #: object (Table 1's relative position; fish 0.5, humans 3).
    #: Swept (#43; 12 fish/busts at 1x, seed 0, macro part transfer; the default 0.814/0.776, seed
    #: to seed 0.004/0.014), at half and twice each preset's: fish 0.25 -> 0.814, 1 -> 0.814 (parts
    #: in one palette 96 % against 99 %); busts 0.5 -> 0.776, 2 -> 0.772. Registered, it acts only
    #: where the relief disagrees (relief_disagreement).
    #: Relief plates/scales at 320x240, seam/rim F1 (the default 0.970/0.972): (the fish preset's
    #: 0.5) 0.25 -> 0.974/0.972, 1 -> 0.963/0.969.
    position_weight: float = setting(1.0, minimum=0.0)
    #: Register each example onto the query (a smooth non-rigid warp of the whole object,
    #: :mod:`imagemap.depth.register`) and compare positions where the warp puts the
    #: example's pixels, instead of positions relative to each object's centroid: the
    #: copy then follows whole example regions, bent with the object (12 fish at 1x:
    #: 70 fragments for 90 % of the object -> 20, 6 at 4x: 1,488 -> about 50; parts in
    #: one palette 46 % -> 97 %; docs/presets.md). False: the paper's relative position.
    registration: bool = setting(True, kind="bool")
    #: The position weight when registered: strong, so that a window leaves the place the
    #: warp gives it only where its relief and colours call for it (4: 26-29 fragments
    #: on 1x fish, 16: 8-12; 12 fish, 12 busts measured).
    registered_position_weight: float = setting(16.0, minimum=0.0)
    #: The object size (square root of its area, pixels of a level) at which
    #: ``registered_position_weight`` holds; at a level where the object is larger the
    #: weight grows with its size, so that a pixel of drift from the warp costs the same
    #: at any resolution (4x fish: 1,488 fragments without, about 50 with).
    #: Swept (#43; 12 fish/busts at 1x, seed 0, macro part transfer; the default 0.816/0.778):
    #: 50 -> 0.818/0.785 (fragments 18.5/6.5), 200 -> 0.816/0.777: within the busts' seed
    #: spread (0.014).
    registered_reference_size: float = setting(100.0, minimum=0.0)
    #: Where none of the registered examples' relief agrees with the query's (a groove,
    #: ridge or bump that lies elsewhere or nowhere in them), the registered position
    #: gives way to the paper's relative position (``position_weight``), and the windows
    #: follow the query's own relief: agreement 1 / (1 + D / this), D the squared
    #: difference of the units-free relief details (in (-1, 1)) averaged over
    #: ``relief_detail_scale`` of the object
    #: (:func:`imagemap.depth.register.position_scales`; 0: off). #42's plates (seam F1
    #: at 320x240 / 768x576, with the seams' relief at 0.5): 0.77 / 0.69 off, 0.97 / 0.94
    #: at 0.05, 0.97 / 0.93 at 0.1; 12 humans: fragments for 90 % 22 / 20, macro part
    #: transfer 0.862 / 0.866 at 0.05 / 0.1. The same factor (its square root) weighs the
    #: seams' graph cut per pixel, so that it does not merge the relief-following matches
    #: back into the examples' layout (#42's scales at 768x576: rim F1 0.89 -> 0.95).
    relief_disagreement: float = setting(0.1, minimum=0.0)
    #: Factor on the registered position weight at the feature level, where the final
    #: reseed draws the small features by their relief, and at the finer levels of a large
    #: map, which must keep them: the warp places an eye or lips within a few pixels only
    #: (12 busts' eyes 0.69 -> 0.79, lips 0.48 -> 0.61 of their pixels from the same part
    #: at 0.25; at 4x, the full weight at the finer levels erased a third of the fish's
    #: eyes; humans, with no small feature, keep 1).
    registered_feature_factor: float = setting(0.25, minimum=0.0)
    #: The final reseed may take a feature from any example (the example preference does
    #: not apply to it), while the EM keeps each region's example (12 busts: brows 0.50
    #: -> 0.53 of their pixels from brows).
    free_final_reseed: bool = setting(True, kind="bool")
    #: The coarser levels' luminance is an extra guide band, weighted like Y at levels
    #: finer than ``Pyramid.context_fraction`` (a large map's fine levels keep the eyes,
    #: lips and palette the coarser levels chose; Cb and Cr too gave the same maps for 10 %
    #: more memory at 1024^2; a weight of its own, 0.5 or 2 times Y, made no measurable
    #: difference, #43). This is its factor at the other levels but the coarsest: weak, so
    #: the level's own band still draws small features while coarser colours decide between
    #: examples whose bands fit alike (200x150 busts with every feature 75 -> 83 %; full
    #: weight lost fish eyes).
    wide_context_weight: float = setting(0.25, minimum=0.0)

    def __post_init__(self) -> None:
        check_settings(self)


@dataclass(frozen=True)
class Matching:
    """The engine's matching: colour bands, search and the EM."""

    #: Weight of Y, and of Cb and Cr, per band standard deviation.
    #: Swept (#43; 12 fish/busts at 1x, seed 0, macro part transfer; the default 0.814/0.776, seed
    #: to seed 0.004/0.014): Y 0.5 -> 0.818/0.766 (busts' features 93 %), 2 -> 0.813/0.774; Cb, Cr
    #: 0.25 -> 0.815/0.776, 1 -> 0.810/0.786 (within the busts' spread).
    #: Relief plates/scales at 320x240, seam/rim F1 (the default 0.970/0.972): Y 0.5 -> 0.979/0.972,
    #: 2 -> 0.919/0.958; Cb, Cr 0.25 -> 0.973/0.970, 1 -> 0.961/0.968.
    luma_weight: float = setting(1.0, minimum=0.0)
    chroma_weight: float = setting(0.5, minimum=0.0)
    #: Fraction of the PCA basis kept, for guide and colour windows (the paper: a fifth).
    #: Swept (#43; 12 fish/busts at 1x, seed 0, macro part transfer; the default 0.814/0.776, seed
    #: to seed 0.004/0.014): 0.1 -> 0.816/0.768; 0.4 -> 0.814/0.783 in 1.5-2x the time.
    #: Relief plates/scales at 320x240, seam/rim F1 (the default 0.970/0.972): 0.1 -> 0.974/0.969,
    #: 0.4 -> 0.963/0.972.
    pca_fraction: float = setting(0.2, minimum=1e-6, maximum=1.0)
    #: Nearest-neighbour search (patchmatch: fastest; exact: the reference).
    #: Exact search lowers the final target by 6-9 % at 10-30x the time and moves SSIM by at most
    #: 0.003 (docs/performance.md, docs/presets.md); pynndescent compiles for about 90 s in every
    #: new process here.
    backend: str = setting("patchmatch", kind="choice", choices=BACKENDS)
    #: EM iterations per level at most, and the relative decrease of the target below
    #: which a level stops. 5 against 8 (12 objects per class, 2026-11-28): macro part
    #: transfer fish 0.809 / 0.808, busts 0.788 / 0.789, humans 0.866 / 0.866, plates'
    #: seam F1 0.97 / 0.96; the finest level had run 6-8 iterations, a fifth of the time.
    max_iterations: int = setting(5, kind="int", minimum=0)
    #: Swept (#43; 12 fish/busts at 1x, seed 0, macro part transfer; the default 0.814/0.776, seed
    #: to seed 0.004/0.014): (tolerance) 0.001 -> 0.813/0.775, 0.004 -> 0.814/0.774: the iteration
    #: cap decides.
    #: Relief plates/scales at 320x240, seam/rim F1 (the default 0.970/0.972): 0.001 -> the same,
    #: 0.004 -> 0.971/0.973.
    tolerance: float = setting(2e-3, minimum=0.0)
    #: "gaussian": each level matches and copies its plain YCbCr colours, so a copied
    #: pixel keeps the colour the coarser levels chose (busts' macro part transfer 0.71 ->
    #: 0.81); "laplacian": the paper's bands, collapsed at the end.
    appearance_pyramid: str = setting("gaussian", kind="choice", choices=APPEARANCE_PYRAMIDS)
    #: Extra window cost per rank of a selected example (the nearest costs nothing): each
    #: region of the object from one example where it fits at all, so that one palette
    #: holds per part (with registration, 30 at every level: 12 fish and 12 busts in one
    #: palette per part in 97 % and 96 % of parts; 3 left 33 % of fish with two palettes
    #: in a part). 0 is the paper's method.
    example_preference: float = setting(30.0, minimum=0.0)
    #: Apply the preference at the feature level and finer too (the final reseed may
    #: still take a feature from another example, see ``Guides.free_final_reseed``).
    #: Swept (#43; 12 fish/busts at 1x, seed 0, macro part transfer; the default 0.816/0.778):
    #: False -> 0.820/0.786 and ΔE00 33.06 against 33.62 on fish, fragments 21.5/9.5 against
    #: 20.5/8.5: within the busts' spread, a candidate to look at with more seeds.
    preference_at_finest: bool = setting(True, kind="bool")
    #: Per level, where the propagated matches fit the depth worst, matches on depth and
    #: position alone replace them when they fit in less than this fraction of the
    #: distance (0: off): features only the finer levels resolve are drawn.
    #: Swept (#43; 12 fish/busts at 1x, seed 0, macro part transfer; the default 0.816/0.778):
    #: 0.25 -> 0.817/0.786, 0.75 -> 0.815/0.778 (busts' seed spread 0.014).
    guide_reseed: float = setting(0.5, minimum=0.0, below=1.0)

    def __post_init__(self) -> None:
        check_settings(self)


@dataclass(frozen=True)
class Finish:
    """How the finest level's matches make the map."""

    #: "copy": every pixel copied from the example pixel most of its windows agree on,
    #: seams blended in the gradient domain (crisp); "mean": the paper's M-step (the
    #: Gaussian-weighted mean of the windows: smooth, blurred where they disagree);
    #: "mode": copying inside the EM iterations too.
    #: The evaluation's mean_vote against full (docs/quality.md, 12 per class): blur ratio 0.61/0.73
    #: against 0.99/0.97 on fish/busts, a quarter of busts missing a feature.
    vote: str = setting("copy", kind="choice", choices=VOTES)
    #: Weight of the seam costs, per 100 px of the object's size, when the copy's sources
    #: are rearranged by graph cuts so that a few large copies remain and seams fall
    #: where the sources agree (Kwatra et al. 2003; 0: off). Per size: the colour costs
    #: grow with a copy's area, its seams with its length only, so a fixed weight would
    #: merge less the finer the map. 12 fish: 1.4 lost 1 eye in 12, 0.14 left 13
    #: fragments, 0.4 draws every eye with 14.5 (ICM, before: 20).
    #: Swept (#43; 12 fish/busts at 1x, seed 0, macro part transfer; the default 0.814/0.776, seed
    #: to seed 0.004/0.014): 0.2 -> 0.813/0.775 (fragments 24.5/8); 0.8 -> 0.815/0.779 (fragments
    #: 19/8.5, fish parts in one palette 96 % against 99 %).
    #: Relief plates/scales at 320x240, seam/rim F1 (the default 0.970/0.972): 0.2 -> 0.970/0.981
    #: (scales' PSNR 19.9 against 19.1: fewer, larger copies hold the examples' layout less), 0.8 ->
    #: 0.951/0.929.
    seam_smoothness: float = setting(0.4, minimum=0.0)
    #: How far one move of that rearrangement may spread a copy, in units of the copy's
    #: own size (the square root of its area): a move's cost grows with its reach. On a
    #: 2048x1536 fish 1 / 2 / 3 left 74 / 35 / 31 fragments in 5.2 / 7.7 / 9.8 s.
    seam_spread: float = setting(2.0, minimum=0.0)
    #: Above this many pixels (of the map's crop) the rearrangement is solved coarse to
    #: fine: on 2x2 blocks, recursively down to this size, then at each finer level only
    #: in a band around the coarser seams (Lombaert et al. 2005; 0: never). The full
    #: solve's time grows faster than its pixels (512^2 1.2 s, 1024^2 12-16 s, 4096^2 214
    #: s) and it leaves more fragments the larger the map. 512^2: maps up to it unchanged;
    #: the ellipsoid fish at 1024^2 (896x1011): 12.8 -> 2.6 s, same energy, 24 fragments
    #: instead of 25 (256^2 = 65536, a coarsest level 4x smaller: energy 10 % higher); a
    #: 2048^2 fish 73 -> 56 fragments; 4096^2: 214 -> 18.5 s (docs/performance.md).
    seam_coarse_above: int = setting(512 * 512, kind="int", minimum=0)
    #: Half-width in pixels of that band. Ellipsoid fish at 1024^2, energy against the
    #: full solve's: 2 px +1.4 %, 4 px +0.0 %, 8 px -0.9 % in 1.4x 4 px's time.
    seam_band: int = setting(4, kind="int", minimum=1)
    #: The relief's detail (units-free, in (-1, 1)) as one more channel, times this, of
    #: the colours the seams' graph cut compares: whole copies whose relief fits the
    #: query's win, and seams avoid crossing relief (a copy's groove lands on the query's
    #: groove, not beside it; 0: colours only). #42's plates at 768x576: seam F1 0.72
    #: off, 0.93 at 0.5, 0.93 at 1; 12 humans' fragments for 90 %: 8 off, 20 at 0.5, 25
    #: at 1.
    seam_relief_weight: float = setting(0.5, minimum=0.0)
    #: In the seams' graph cut, a pixel copied from the example of rank r (the engine's
    #: order, nearest first) costs r times this (squared colour units, channels in
    #: [0, 1]): the same preference the matching has (``example_preference``), so that
    #: the relief's channel does not hand a part to another example's palette. 12 fish:
    #: objects with one palette per part 75 % at 0, 92 % at 0.03, 0.1 and 0.3 (macro part
    #: transfer 0.812, 0.806, 0.806, 0.806); 12 busts 92 % at 0 and 0.3; plates' seam F1
    #: unchanged. Stronger, the copy leaves the voted colours more and the blend corrects
    #: more (a test blob's copy-to-map gap 0.003 at 0, 0.02 at 0.3).
    seam_example_preference: float = setting(0.03, minimum=0.0)
    #: Copy whole every small feature of an example (eye, lips, brow) that the copy cut:
    #: busts with every feature 92 -> 100 % (4x: 67 -> 83 %).
    complete_features: bool = setting(True, kind="bool")
    #: How far the copy may drift towards the voted colours in the seam blend, as a
    #: fraction of the object's size (8 px for a 200x150 fish, 85 px at 2048^2).
    #: Swept (#43; 12 fish/busts at 1x, seed 0, macro part transfer; the default 0.816/0.778):
    #: 0.05 and 0.2 -> 0.816/0.778 (blur ratio 0.977/0.980 and 0.994/0.986: the drift trades
    #: ΔE00 33.48 / 33.90 for crispness).
    blend_scale: float = setting(0.1, minimum=0.0)
    #: Keep a step one pixel sharp where the copy changes source inside one example and
    #: the voted map shows at least this share of it (a sleeve meeting a hand; 0: blend
    #: every seam): blur ratio fish 0.93 -> 0.97, humans 0.88 -> 0.97.
    edge_support: float = setting(0.3, minimum=0.0, maximum=1.0)
    #: A seam's step counts as an edge (for ``edge_support``) when it is at least this many
    #: times as strong as either side's own gradient; weaker steps are texture, continued
    #: by the stronger side (12 objects per class: 3 or 4 instead of 2 moved ΔE00, SSIM
    #: and the blur ratio by at most 0.04, 0.001 and 0).
    edge_contrast: float = setting(2.0, minimum=0.0)
    #: ...and when it is at least this large (norm of the YCbCr step, channels in [0, 1]:
    #: about ΔE00 5 for a step in luminance alone). Two offsets of smooth skin differ by a
    #: few hundredths of shading, which passed the contrast test next to smooth sides and
    #: drew a blocky face at 4x; the kept steps fall into two groups, under 0.04 (shading)
    #: and from 0.06 (part edges). With it 4x fish SSIM 0.588 -> 0.597, busts 0.673 ->
    #: 0.677; 0.03 left some tiles, 0.06 and 0.1 looked like 0.05.
    edge_floor: float = setting(0.05, minimum=0.0)

    def __post_init__(self) -> None:
        check_settings(self)

    @property
    def copies(self) -> bool:
        """Whether the map is copied from example pixels (not the engine's vote)."""
        return self.vote in ("copy", "mode")


@dataclass(frozen=True)
class Completion:
    """Which small features the copy completes, and how (:mod:`imagemap.depth.completion`;
    on or off: ``Finish.complete_features``). ``docs/presets.md`` ("Small features copied
    whole") has the measurements, on the 12 generated objects per class unless said; a
    field whose comment gives no measurement was set with its step and not swept. A
    "Swept" line (#43) gives the macro part transfer of 12 busts at 1x, 6 at 4x and 12
    fish, seed 0, every value on the same synthesis (the stages up to the copy run once),
    so that the differences are the completion's own; from seed to seed the figure moves by
    0.014, 0.001 and 0.004 (3 seeds, 2 at 4x). Features drawn: 1.00, 0.97 and 1.00 unless
    said. The doubles' thresholds made no measurable difference: constants of
    :mod:`imagemap.depth.completion`."""

    #: A feature is at most this share of the object's size (square root of its area)
    #: across: an eye, lips, a brow; not a stripe, a sleeve or hair (0.15 or 0.25 moved
    #: the macro part transfer by at most 0.011).
    feature_extent: float = setting(0.2, minimum=0.0)
    #: Its colour stands out from its surroundings' (their median) by at least this much
    #: (YCbCr distance; lips on skin 0.09, an eye 0.3, shading under 0.03; at 0.1 the
    #: busts' lips were no longer features).
    #: Swept (docs/presets.md, the engine of 2026-11-25; 12 fish / 12 busts / busts at 4x):
    #: 0.05 -> 0.777/0.824/0.818 against 0.778/0.817/0.806, nearer the blushes' and
    #: shading's contrasts; 0.1 -> the lips (0.09) no longer features.
    feature_contrast: float = setting(0.07, minimum=0.0)
    #: More components of one colour than this are a texture's elements, not features (a
    #: checked shirt's squares were "completed" at 4x without it).
    #: Swept (busts 1x/4x, fish, see above): 2 -> 0.755/0.831/0.806, 3 of 12 busts at 1x with a
    #: feature not drawn (features 0.95); 4 -> 0.775/0.836/0.806; 8 -> 0.775/0.836/0.806 (seed to
    #: seed: 0.014, 0.001, 0.004).
    max_repeats: int = setting(4, kind="int", minimum=0)
    #: The share of the pixels around a feature that must be of one colour (its ground):
    #: not a blush, nor a shirt's corner cut by a neckline (one put an orange glow into
    #: busts_003's V-neck at 4x). On a ground of several colours (an eye across a fish's
    #: bands), the share of them that must step away from the feature's edge instead.
    #: Swept (busts 1x/4x, fish, see above; the default now 0.776/0.840/0.814): 0.6 ->
    #: 0.774/0.840/0.812; 0.95 -> 0.772/0.841/0.814: within the spread.
    surround_share: float = setting(0.8, minimum=0.0, maximum=1.0)
    #: A feature on a ground of several colours has no more pixels of its colour than its
    #: own within this many of its widths around it: not a check of a shirt, nor a piece
    #: of a stripe between others (at 1 width, pieces of fish_007's tail stripes were
    #: features; at 2, the 48 generated examples gained 28: 8 eyes, a fish's eye with the
    #: band around it, a brow, 11 shoes and 7 small pieces of fins, clothes and skin).
    #: Swept (busts 1x/4x, fish, see above; the default now 0.776/0.840/0.814): 1 ->
    #: 0.776/0.840/0.812; 4 -> 0.776/0.840/0.814: within the spread.
    rare_reach: float = setting(2.0, minimum=0.0)
    #: The share of those pixels that must lie inside the object: a shirt's stripe cut by
    #: the neckline, completed into a smudge at busts_000's neck at 4x, is no feature.
    #: Swept (busts 1x/4x, fish, see above; the default now 0.776/0.840/0.814): 0.4 ->
    #: 0.776/0.840/0.814 (one 4x bust's map moved, 0.8402 against 0.8401); 0.95 ->
    #: 0.776/0.840/0.814: no measurable effect.
    inside_share: float = setting(0.75, minimum=0.0, maximum=1.0)
    #: The host colour's median window, in pixels of the resolution it is taken at: the
    #: host varies slowly, and a large window's median is slow.
    #: Swept (busts 1x/4x, fish, see above): 5 -> 0.777/0.836/0.806; 9 -> 0.775/0.836/0.806; 17 ->
    #: 0.774/0.840/0.806 (seed to seed: 0.014, 0.001, 0.004).
    host_window: int = setting(9, kind="int", minimum=1)
    #: An instance that copies at least this share of the feature's pixels counts as drawn
    #: whole and is left alone.
    #: Swept (busts 1x/4x, fish, see above): 0.7 -> 0.775/0.831/0.806; 0.8 -> 0.775/0.836/0.806; 0.9
    #: -> 0.776/0.836/0.801, and every 4x bust with every feature (6 of 6, features 1.00, against
    #: 5 and 0.97) (seed to seed: 0.014, 0.001, 0.004).
    complete_share: float = setting(0.8, minimum=0.0, maximum=1.0)
    #: An instance copying less than this share is a stray fragment, not an attempt to draw
    #: the feature: left alone too (0.2, 0.3 and 0.4 gave the same macro part transfer).
    partial_share: float = setting(0.2, minimum=0.0, maximum=1.0)
    #: A feature none of whose pixels the map copies is still completed where the map
    #: copies at least this share of its ring (the pixels within half its width around it)
    #: at offsets near one another: its surroundings were taken and it was skipped
    #: (busts_003's eye at 4x: 0.31; busts_009's lips: between 0.2 and 0.3).
    #: Swept (busts 1x/4x, fish, see above; the default now 0.776/0.840/0.814): 0.1 and 0.4 ->
    #: 0.776/0.840/0.814, every figure as at 0.2 (nor with no skipped feature completed at
    #: all, ``skipped_place_shown`` 0). The step acts on 2 of 36 busts of seed 1 (busts_012's
    #: and busts_025's brows, drawn only by it; looked at): their macro part transfer 0.721
    #: at 0.1 and 0.2, 0.718 at 0.4 and with the step off (features 90.6 against 91.1 %).
    skipped_ring_share: float = setting(0.2, minimum=0.0, maximum=1.0)
    #: A skipped feature is not completed where this share of its place already stands out
    #: from its surroundings in the map: something is drawn there (it refused a blue-grey
    #: eye over busts_008's own brown one).
    #: Swept (busts 1x/4x, fish, see above; the default now 0.776/0.840/0.814): 0.15 and 0.6 ->
    #: 0.776/0.840/0.814, every figure as at 0.3; 0 (no skipped feature completed) too. 36
    #: busts of seed 1: 0.15 and 0.6 as at 0.3 (0.721), 0 -> 0.718 (two brows not drawn).
    skipped_place_shown: float = setting(0.3, minimum=0.0, maximum=1.0)
    #: Pixels of surroundings copied with the feature around it.
    #: Swept (busts 1x/4x, fish, see above): 1 -> 0.780/0.833/0.806; 2 -> 0.775/0.836/0.806; 4 ->
    #: 0.773/0.839/0.806 (seed to seed: 0.014, 0.001, 0.004).
    rim: int = setting(2, kind="int", minimum=0)
    #: The rim's largest mean colour difference (YCbCr) from what the map shows there
    #: (without it an orange glow went into a V-neck; at 0.14 every 4x bust drew every
    #: feature, but a brow's skin rim glowed as a light patch).
    #: Swept (busts 1x/4x, fish, see above; the default now 0.776/0.840/0.814): 0.035 ->
    #: 0.776/0.840/0.814; 0.14 -> 0.777/0.846/0.814 (beyond the 4x spread, but 1x busts' parts with
    #: one palette 99 -> 97 %).
    rim_agreement: float = setting(0.07, minimum=0.0)

    def __post_init__(self) -> None:
        check_settings(self)


@dataclass(frozen=True)
class DepthConfig:
    """Everything a depth-map colorization does, in one frozen value.

    Examples
    --------
    >>> config = DepthConfig()
    >>> config.pyramid.patch_sizes, config.finish.vote
    ((7, 11, 9), 'copy')
    >>> config.replace_fields(vote="mean").finish.vote
    'mean'
    """

    selection: Selection = field(default_factory=Selection)
    pyramid: Pyramid = field(default_factory=Pyramid)
    registration: Registration = field(default_factory=Registration)
    guides: Guides = field(default_factory=Guides)
    matching: Matching = field(default_factory=Matching)
    finish: Finish = field(default_factory=Finish)
    completion: Completion = field(default_factory=Completion)

    def replace_fields(self, **values: Any) -> DepthConfig:
        """A copy with fields replaced by their own name, whatever group holds them.

        Examples
        --------
        >>> DepthConfig().replace_fields(m=1, patch_sizes=(7,)).pyramid.patch_sizes
        (7,)
        """
        groups: dict[str, dict[str, Any]] = {}
        for name, value in values.items():
            group = _FIELD_GROUPS.get(name)
            if group is None:
                raise InputError(f"unknown setting {name!r}; known: {', '.join(_FIELD_GROUPS)}")
            groups.setdefault(group, {})[name] = value
        return replace(
            self,
            **{g: replace(getattr(self, g), **changes) for g, changes in groups.items()},
        )

    def flat(self) -> dict[str, Any]:
        """Every field by its own name (for reports and digests)."""
        return {
            f.name: getattr(getattr(self, group), f.name)
            for group in _GROUPS
            for f in fields(getattr(self, group))
        }


_GROUP_TYPES: dict[str, type] = {
    "selection": Selection,
    "pyramid": Pyramid,
    "registration": Registration,
    "guides": Guides,
    "matching": Matching,
    "finish": Finish,
    "completion": Completion,
}
_GROUPS = tuple(_GROUP_TYPES)
#: Field name -> the group that holds it (field names are unique across groups).
_FIELD_GROUPS = {f.name: group for group, cls in _GROUP_TYPES.items() for f in fields(cls)}


def _preset(
    m: int, patch_sizes: tuple[int, ...], position_weight: float, feature_factor: float = 0.25
) -> DepthConfig:
    return DepthConfig(
        selection=Selection(m=m),
        pyramid=Pyramid(patch_sizes=patch_sizes),
        guides=Guides(position_weight=position_weight, registered_feature_factor=feature_factor),
    )


#: Class presets after the paper's Table 1 (m and windows as published; weights
#: restated per band standard deviation, see ``docs/presets.md``).
PRESETS: dict[str, DepthConfig] = {
    # Humans: no small feature to draw by relief at 150x200, and the whole position weight
    # at the finest level keeps 12 figures in 9 fragments (52 at 0.25).
    "humans": _preset(1, (7, 9, 9), 3.0, feature_factor=1.0),
    "busts": _preset(2, (7, 11, 9), 1.0),
    "fish": _preset(2, (7, 11, 9), 0.5),
    # Shells: the plates' layout is each shell's own, so the relief must lead (its band 4x
    # the fish's: 12 shells' macro part transfer 0.756 -> 0.864, grooves and plates in
    # their places, against 0.826 at 2x), from one example (no second palette to mix).
    "shells": replace(
        _preset(1, (7, 11, 9), 0.5),
        guides=replace(Guides(), position_weight=0.5, depth_detail_weight=8.0),
    ),
}


def _one_pass(config: DepthConfig) -> DepthConfig:
    # Fig. 1: one scale, windows of the paper's k, depth only, one vote.
    return config.replace_fields(
        patch_sizes=config.pyramid.patch_sizes[:1],
        max_iterations=0,
        position_weight=0.0,
        registration=False,
        vote="mean",
        grow=False,  # one level: Fig. 1 has no pyramid
    )


#: The methods ``imagemap evaluate`` compares, in report order: name -> how its
#: configuration is made from the class preset (with the run's options); None for a
#: baseline that synthesizes nothing (``copy_nearest``: the nearest example's map pasted
#: at the query's centroid; ``warp_nearest``: the first-choice example posed and warped
#: onto the query as the method does, copied whole). Declared once: the command line,
#: the evaluation and the report read it.
METHODS: dict[str, Callable[[DepthConfig], DepthConfig] | None] = {
    "full": lambda config: config,
    "copy_nearest": None,
    "warp_nearest": None,
    "one_pass": _one_pass,
    "mean_vote": lambda config: config.replace_fields(vote="mean"),
    "no_position": lambda config: config.replace_fields(position_weight=0.0, registration=False),
    "laplacian": lambda config: config.replace_fields(appearance_pyramid="laplacian"),
    "paper": lambda config: config.replace_fields(**FINISHES["paper"]),
}


def apply_options(config: DepthConfig, **options: Any) -> DepthConfig:
    """``config`` with the :data:`OPTIONS` given (None: unset) applied.

    A named ``finish`` is applied first, so that options given beside it win.

    Raises
    ------
    InputError
        An unknown option or a value the configuration refuses (naming the option).
    """
    unknown = sorted(set(options) - set(OPTION_NAMES))
    if unknown:
        raise InputError(
            f"unknown option {', '.join(unknown)}; the options are {', '.join(OPTION_NAMES)}"
        )
    values = {name: value for name, value in options.items() if value is not None}
    finish = values.pop("finish", None)
    settings: dict[str, Any] = {}
    if finish is not None:
        if finish not in FINISHES:
            raise InputError(f"finish: unknown {finish!r}; use one of {', '.join(FINISHES)}")
        settings.update(FINISHES[finish])
    for name, value in values.items():
        option = OPTION_NAMES[name]
        if option.kind in ("switch_on", "switch_off") and not isinstance(value, bool):
            raise InputError(f"{name}: expected True or False, got {value!r}")
        if option.kind == "choice" and value not in option.choices:
            raise InputError(f"{name}: unknown {value!r}; use one of {', '.join(option.choices)}")
        settings[option.setting] = value  # type: ignore[index]
    return config.replace_fields(**settings) if settings else config


def resolve_config(preset: str | DepthConfig | None = None, **options: Any) -> DepthConfig:
    """The configuration of a class preset (a name, a :class:`DepthConfig`, or None for
    the default) with the :data:`OPTIONS` given applied.

    Examples
    --------
    >>> resolve_config("humans").selection.m
    1
    >>> resolve_config("cats")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    imagemap.errors.InputError: preset: unknown preset 'cats'; use one of [...]
    """
    if preset is None:
        config = DepthConfig()
    elif isinstance(preset, DepthConfig):
        config = preset
    elif isinstance(preset, str) and preset in PRESETS:
        config = PRESETS[preset]
    elif isinstance(preset, str):
        raise InputError(f"preset: unknown preset {preset!r}; use one of {sorted(PRESETS)}")
    else:
        raise InputError(f"preset: expected a preset name or DepthConfig, got {preset!r}")
    return apply_options(config, **options)
