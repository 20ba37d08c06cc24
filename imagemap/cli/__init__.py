"""The ``imagemap`` command: a thin layer over the Python API.

Each topic registers its subcommands from its own module (listed in
``SUBCOMMAND_MODULES``): a module exposes ``register(subparsers)`` and sets
``func`` on each parser it adds; ``func(args)`` returns the exit code. A module
that makes a command group (``imagemap btf``) returns ``{group: subparsers}``;
the modules of ``GROUP_MODULES`` add their subcommands to that group.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import sys

from imagemap.io import InputError

SUBCOMMAND_MODULES = [
    "imagemap.cli.synthesize",
    "imagemap.cli.btf",
    "imagemap.cli.evaluate",
    "imagemap.cli.bench",
    "imagemap.cli.batch",
]

#: Modules adding subcommands to a group made by a module above: group -> modules.
GROUP_MODULES = {"btf": ["imagemap.cli.btf_ma"]}

EPILOG = """\
examples:
  imagemap synthesize query_depth.png --db fish_db/ -o map.png --preset fish
  imagemap db check fish_db/
  imagemap evaluate fish_db/ --out report/
  imagemap btf experiment --out table2/

Run 'imagemap COMMAND --help' for the options of each command.
"""


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="imagemap",
        description=(
            "Example-based synthesis of image-maps: give the depth map of a new object and a "
            "database of similar objects with their image-maps, get a colour image-map "
            "tailored to the new object's 3D features. The same engine extrapolates measured "
            "materials (BTFs) from a small sample and four scanner images."
        ),
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=_version())
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    groups: dict[str, argparse._SubParsersAction] = {}
    for name in SUBCOMMAND_MODULES:
        groups.update(importlib.import_module(name).register(subparsers) or {})
    for group, names in GROUP_MODULES.items():
        for name in names:
            importlib.import_module(name).register(groups[group])
    return parser


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return f"imagemap {version('imagemap')}"
    except PackageNotFoundError:
        return "imagemap (not installed)"


def add_common_options(parser: argparse.ArgumentParser) -> None:
    """Options every long-running subcommand shares."""
    parser.add_argument(
        "-q", "--quiet", action="store_true", help="no progress bar and no log lines"
    )
    parser.add_argument("-v", "--verbose", action="store_true", help="log the engine's steps")


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:
        if exc.code == 2:  # argparse printed the error naming the option: exit code 2
            return 2
        raise  # --help, --version
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    level = logging.WARNING
    if getattr(args, "verbose", False):
        level = logging.INFO
    if getattr(args, "quiet", False):
        level = logging.ERROR
    logging.basicConfig(level=level, format="imagemap: %(message)s", stream=sys.stderr)
    try:
        return int(args.func(args) or 0)
    except InputError as exc:
        print(f"imagemap: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("imagemap: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
