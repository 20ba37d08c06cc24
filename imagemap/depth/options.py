"""The options a user may set from the command line, a batch or the Python API.

Declared once: :data:`OPTIONS` makes the CLI's flags (:mod:`imagemap.cli.options`),
:class:`imagemap.batch.BatchOptions` and :func:`imagemap.colorize`'s keywords, and
:func:`imagemap.depth.config.apply_options` applies them to a configuration.

Apart from :mod:`imagemap.depth.config` so that the command line can build its parser
without making the configuration's dataclasses (about 15 ms of every start, ``imagemap
synthesize --help`` included); this module imports nothing but the choices' names.

Examples
--------
>>> OPTION_NAMES["vote"].choices
('copy', 'mean', 'mode')
"""

from __future__ import annotations

from typing import Any, NamedTuple

from imagemap.core.choices import APPEARANCE_PYRAMIDS, BACKENDS, VOTES

__all__ = ["FINISHES", "OPTIONS", "OPTION_NAMES", "Option"]

#: Named finishes: field values that make a known method. "paper" is Hassner & Basri's
#: own: positions relative to each object's centroid (no registration), no example
#: preference, the mean M-step on YCbCr Laplacian bands, collapsed, and no finishing
#: stage (on our guide bands).
FINISHES: dict[str, dict[str, Any]] = {
    "copy": {},
    "paper": {
        "registration": False,
        "example_preference": 0.0,
        "preference_at_finest": False,
        "vote": "mean",
        "appearance_pyramid": "laplacian",
        "complete_features": False,
    },
}


class Option(NamedTuple):
    """One setting a user may change from the command line, a batch or the API.

    ``name`` is the keyword (``colorize(..., vote="mean")``) and the argparse
    destination; ``setting`` the :class:`DepthConfig` field it sets (None: a named
    bundle of fields, see :data:`FINISHES`); ``flag`` the command-line flag; ``kind``
    how the flag reads its value: ``"choice"``, ``"positive_int"``,
    ``"non_negative_float"``, ``"fraction"``, ``"switch_on"`` (a flag that sets True)
    or ``"switch_off"`` (a flag that sets False).
    """

    name: str
    setting: str | None
    flag: str
    kind: str
    help: str
    choices: tuple[str, ...] = ()


#: The options of a depth-map colorization, declared once.
OPTIONS: tuple[Option, ...] = (
    Option("m", "m", "--m", "positive_int", "number of examples to select automatically (>= 1)"),
    Option(
        "backend",
        "backend",
        "--backend",
        "choice",
        "nearest-neighbour search (default patchmatch: fastest; exact: reference)",
        BACKENDS,
    ),
    Option(
        "example_preference",
        "example_preference",
        "--example-preference",
        "non_negative_float",
        "extra cost per rank of a selected example (default 30): each region of the "
        "object from the nearest example where it fits at all, one palette per part; "
        "0 is the paper's method",
    ),
    Option(
        "vote",
        "vote",
        "--vote",
        "choice",
        "how matched windows make the map: copy (default; each pixel copied from the example "
        "pixel its windows agree on, seams blended: crisp eyes and stripes), mean (the "
        "paper: weighted mean of the windows, smooth but blurred), mode (copying inside "
        "the EM iterations too)",
        VOTES,
    ),
    Option(
        "appearance_pyramid",
        "appearance_pyramid",
        "--appearance-pyramid",
        "choice",
        "what each pyramid level matches and copies: gaussian (default; the level's plain "
        "colours, so a copied pixel keeps the colour the coarser levels chose), laplacian "
        "(the paper's YCbCr Laplacian bands)",
        APPEARANCE_PYRAMIDS,
    ),
    Option(
        "edge_support",
        "edge_support",
        "--edge-support",
        "fraction",
        "where the copy changes source inside one example and the step there is an edge the "
        "voted map shows too (a sleeve meeting a hand), keep it one pixel sharp if the vote "
        "shows at least this share of it (default 0.3); 0 blends every seam",
    ),
    Option(
        "complete_features",
        "complete_features",
        "--no-feature-completion",
        "switch_off",
        "leave an example's eye, lips or brow as the copy cut it (by default a small feature "
        "copied only in part, say lips cut into a lozenge where two offsets meet, is copied "
        "whole)",
    ),
    Option(
        "mirror",
        "mirror",
        "--no-mirror",
        "switch_off",
        "do not try the examples mirrored (by default a query facing the other way than "
        "its examples is made from them mirrored; turn it off for a class that is not "
        "mirror-symmetric: writing, a heart on one side)",
    ),
    Option(
        "finish",
        None,
        "--finish",
        "choice",
        "a named method: copy (default: the settings above) or paper (Hassner & Basri's "
        "own: mean vote on Laplacian colour bands, no finishing stage); options given "
        "beside it override it",
        tuple(FINISHES),
    ),
)

#: Option name -> its declaration.
OPTION_NAMES = {option.name: option for option in OPTIONS}
