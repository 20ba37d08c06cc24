"""``python -m data_gen CLASS --count N --size WxH --seed S --out DIR [--holdout K] [--meshes]``."""

from __future__ import annotations

import argparse
import logging
import sys
import time

from data_gen import CLASSES
from data_gen.dataset import write_class
from data_gen.render import ray_backend
from imagemap.io import InputError
from imagemap.validate import non_negative_int, parse_size


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m data_gen",
        description=(
            "Make a class of procedural objects and render each to a depth map, an "
            "image-map and a part-label map (an imagemap database)."
        ),
        epilog="example: python -m data_gen fish --count 9 --holdout 1 --out examples/fish",
    )
    parser.add_argument("class_name", metavar="CLASS", choices=sorted(CLASSES))
    parser.add_argument("--count", type=int, default=20, help="instances (default 20)")
    parser.add_argument(
        "--size",
        type=parse_size,
        default=None,
        help="WIDTHxHEIGHT (default: fish 200x150, busts and humans 150x200)",
    )
    parser.add_argument(
        "--seed", type=non_negative_int, default=0, help="run seed >= 0 (default 0)"
    )
    parser.add_argument("--out", required=True, help="output directory")
    parser.add_argument(
        "--holdout",
        type=int,
        default=0,
        help="write the last K instances to OUT/holdout/ (queries kept out of the database)",
    )
    parser.add_argument(
        "--meshes",
        action="store_true",
        help="also write each instance as a textured mesh OUT/meshes/NAME.glb "
        "(holdout: OUT/holdout/meshes/), for imagemap's mesh input and batches",
    )
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress bar, no log")
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    logging.basicConfig(
        level=logging.ERROR if args.quiet else logging.INFO,
        format="data_gen: %(message)s",
        stream=sys.stderr,
    )
    start = time.perf_counter()
    try:
        from imagemap.outputs import check_output_directory

        check_output_directory(args.out, "--out directory")
        instances = write_class(
            CLASSES[args.class_name],
            args.out,
            count=args.count,
            seed=args.seed,
            size=args.size,
            holdout=args.holdout,
            quiet=args.quiet,
            meshes=args.meshes,
        )
    except InputError as exc:
        print(f"data_gen: error: {exc}", file=sys.stderr)
        return 2
    if not args.quiet:
        print(
            f"data_gen: {len(instances)} {args.class_name} written to {args.out} in "
            f"{time.perf_counter() - start:.1f} s (ray backend {ray_backend()})",
            file=sys.stderr,
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
