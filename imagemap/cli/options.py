"""Options shared by the commands that synthesize: made from one declaration.

The colorization options are :data:`imagemap.depth.options.OPTIONS`: every command
(``synthesize``, ``batch``, ``evaluate``) adds them with :func:`add_config_options`
and reads them back with :func:`config_options`, so a new option reaches every route
by being declared once. Also here: the mesh options and the background colour,
shared by ``synthesize`` and ``batch``.

Nothing heavy is imported: the parser is built before NumPy is loaded.
"""

from __future__ import annotations

import argparse
from typing import Any

from imagemap.depth.options import OPTIONS
from imagemap.errors import InputError
from imagemap.validate import (
    fraction,
    non_negative_float,
    non_negative_int,
    parse_size,
    positive_int,
)

__all__ = [
    "add_config_options",
    "add_mesh_options",
    "config_options",
    "parse_colour",
    "views_of",
]

_TYPES = {
    "positive_int": positive_int,
    "non_negative_float": non_negative_float,
    "fraction": fraction,
}


def add_config_options(parser: argparse.ArgumentParser) -> None:
    """Add every option of :data:`~imagemap.depth.options.OPTIONS`, and ``--seed``.

    An option not given is None: the preset's value stands.
    """
    group = parser.add_argument_group("method (each overrides the preset)")
    for option in OPTIONS:
        if option.kind == "switch_on":
            group.add_argument(
                option.flag, dest=option.name, action="store_const", const=True, help=option.help
            )
        elif option.kind == "switch_off":
            group.add_argument(
                option.flag, dest=option.name, action="store_const", const=False, help=option.help
            )
        elif option.kind == "choice":
            group.add_argument(
                option.flag, dest=option.name, choices=option.choices, help=option.help
            )
        else:
            group.add_argument(
                option.flag, dest=option.name, type=_TYPES[option.kind], help=option.help
            )
    parser.add_argument(
        "--seed", type=non_negative_int, default=0, help="random seed >= 0 (same seed, same bytes)"
    )


def config_options(args: argparse.Namespace) -> dict[str, Any]:
    """The options of :data:`~imagemap.depth.options.OPTIONS` given on the command line.

    Examples
    --------
    >>> config_options(argparse.Namespace(vote="mean", m=None, seed=0))
    {'vote': 'mean'}
    """
    values = {option.name: getattr(args, option.name, None) for option in OPTIONS}
    return {name: value for name, value in values.items() if value is not None}


class _OneView(argparse.Action):
    """``--view AZ,EL``: one view, instead of the default ``--views auto``."""

    def __call__(self, parser, namespace, values, option_string=None):
        namespace.view = values
        namespace.views = None


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number > 0, got {text!r}") from None
    if not (value > 0 and value < float("inf")):
        raise argparse.ArgumentTypeError(f"expected a number > 0, got {text!r}")
    return value


#: Names of --units (metres per unit: imagemap.scene.files.UNIT_SCALES).
UNIT_NAMES = ("m", "cm", "mm", "in", "ft")


def add_mesh_options(
    parser: argparse.ArgumentParser, uv_space: bool = False, fine_views: bool = False
) -> None:
    """--view, --views, --size, --texture-size, --units, --scale: how meshes are seen,
    textured and written; with ``uv_space``, --uv-space, --no-uv-space and --no-register
    too; with ``fine_views``, --size's default (None) is each mesh's own
    (:func:`imagemap.scene.bake.view_size_for`), else 200x150."""
    group = parser.add_argument_group("meshes (input .glb .obj .ply ...; output .glb or .obj)")
    if uv_space:
        both = group.add_mutually_exclusive_group()  # both given: refused, not the last wins
        both.add_argument(
            "--uv-space",
            dest="uv_space",
            action="store_const",
            const=True,
            default=None,
            help="synthesize in the mesh's UV atlas: the database's textured meshes are in "
            "the query's UV layout (a registered template). Default: when they are found to "
            "be (same UVs, or the same surface point at each texel), else by views",
        )
        both.add_argument(
            "--no-uv-space",
            dest="uv_space",
            action="store_const",
            const=False,
            help="synthesize by views even when the examples share the query's UV layout",
        )
        group.add_argument(
            "--no-register",
            dest="registered",
            action="store_const",
            const=False,
            default=None,
            help="synthesize by views when the database's textured meshes are in other UV "
            "layouts than the query's (default: they are registered to the query in 3-D and "
            "resampled into its atlas: the registered path)",
        )
    group.add_argument(
        "--view",
        action=_OneView,
        help="AZ,EL in degrees: one view only (0,0 is the front, looking along -z as "
        "data_gen); a negative value needs '=': --view=-90,0",
    )
    group.add_argument(
        "--views",
        default="auto",
        help="views baked into the mesh's UV atlas: 'auto' (default: of front, back, top, "
        "bottom, right, left, those that see the surface, chosen by coverage), names "
        "(front,back,left,right,top,bottom) or AZ,EL pairs, e.g. 'front,back' or "
        "'0,0;90,0;180,0'",
    )
    group.add_argument(
        "--size",
        type=parse_size,
        default=None if fine_views else (200, 150),
        help="WIDTHxHEIGHT of each view's depth map (default: 200x150 made finer, its "
        "aspect kept, until one view pixel covers no more of the surface than one texel of "
        "the texture (--texture-size, else the mesh's own texture), up to 317x238: views "
        "coarser than the texels draw their pixels' stair steps into the texture)"
        if fine_views
        else "WIDTHxHEIGHT of each view's depth map (default 200x150)",
    )
    group.add_argument(
        "--texture-size",
        type=positive_int,
        default=None,
        help="texture width and height (default: the resolution of the mesh's UV atlas: "
        "its own texture's size, else chosen from its texel density)",
    )
    scale = group.add_mutually_exclusive_group()
    scale.add_argument(
        "--units",
        choices=UNIT_NAMES,
        help="the input mesh's units; the GLB is written in metres (--units mm: x 0.001). "
        "Default: coordinates kept as they are (read as metres), and the size stated",
    )
    scale.add_argument(
        "--scale",
        type=_positive_float,
        help="multiply the coordinates by this factor when writing (instead of --units)",
    )


def views_of(args: argparse.Namespace) -> tuple:
    """The views ``--views`` or ``--view`` name (default: the front)."""
    from imagemap.scene import FRONT, parse_view, parse_views  # deferred: start-up (SciPy)

    if getattr(args, "views", None) == "auto":  # the candidates; the mesh route narrows them
        from imagemap.scene.coverage import (
            CANDIDATES,
        )  # deferred: start-up: the parser loads no scientific module

        return CANDIDATES
    if getattr(args, "views", None):
        return tuple(parse_views(args.views))
    if getattr(args, "view", None):
        return (parse_view(args.view),)
    return (FRONT,)


def parse_colour(text: str) -> tuple[float, float, float] | None:
    """'transparent' -> None; a named or '#rrggbb' colour -> RGB in [0, 1].

    Examples
    --------
    >>> parse_colour("#ff8000")
    (1.0, 0.5019607843137255, 0.0)
    >>> parse_colour("transparent") is None
    True
    """
    named = {"white": "#ffffff", "black": "#000000", "grey": "#808080", "gray": "#808080"}
    text = named.get(text.lower(), text)
    if text.lower() == "transparent":
        return None
    if len(text) == 7 and text.startswith("#"):
        try:
            red, green, blue = (int(text[i : i + 2], 16) / 255.0 for i in (1, 3, 5))
            return red, green, blue
        except ValueError:
            pass
    raise InputError(f"--background: not a colour: {text!r} (use transparent, white or #rrggbb)")
