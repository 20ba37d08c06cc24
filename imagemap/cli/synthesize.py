"""``imagemap synthesize`` and ``imagemap db check``."""

from __future__ import annotations

import argparse
import json
import logging
import sys
import time
import tracemalloc

from imagemap.io import InputError

log = logging.getLogger("imagemap")

SYNTHESIZE_HELP = """\
Synthesize an image-map for a new depth map from a database of examples.

The database is a directory of NAME_depth.png (8/16-bit; or .tif float, .npy)
beside NAME_image.png. The m examples whose depth is nearest to the query's
(after centroid alignment) are selected automatically, or name them with
--examples. Windows of the query's depth are matched to windows of the
examples' depth and colour, coarse to fine, and the matched colours are merged
(hard EM). Background (depth 0 or NaN) is transparent in the output unless
--background gives a colour.

examples:
  # a fish from a generated database (see the README's first command)
  imagemap synthesize examples/fish/holdout/fish_008_depth.png --db examples/fish \\
      -o fish_map.png --preset fish --provenance fish_provenance.png

  # a whole batch in one process (outputs NAME_image.png in maps/)
  imagemap synthesize crowd/*_depth.png --db humans/ -o maps/ --preset humans

  # two chosen examples, white background, exact search
  imagemap synthesize bust_depth.png --db busts/ -o bust_map.png --preset busts \\
      --examples bust_003,bust_017 --background white --backend exact
"""


def register(subparsers: argparse._SubParsersAction) -> None:
    from imagemap.cli import add_common_options
    from imagemap.cli.batch import add_mesh_options
    from imagemap.colorization import PRESETS
    from imagemap.engine import BACKENDS

    p = subparsers.add_parser(
        "synthesize",
        help="make an image-map for a depth map from a database of examples",
        description=SYNTHESIZE_HELP,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "depth",
        nargs="+",
        help="query depth map(s) (.png 8/16-bit, .tif float, .npy); with several, -o, "
        "--provenance and --preview name directories and each map is written as "
        "NAME_image.png (a database of the results, with the depths beside them)",
    )
    p.add_argument("--db", required=True, help="database directory of NAME_depth/NAME_image pairs")
    p.add_argument("-o", "--output", required=True, help="output image-map (.png, RGBA)")
    p.add_argument(
        "--preset",
        choices=sorted(PRESETS),
        default="busts",
        help="class preset: weights, patch sizes and m after the paper's Table 1 (default busts)",
    )
    p.add_argument("--m", type=int, help="number of examples to select automatically")
    p.add_argument("--examples", help="comma-separated example names to use instead")
    p.add_argument("--exclude", help="comma-separated example names to leave out of the database")
    p.add_argument(
        "--backend",
        choices=BACKENDS,
        help="nearest-neighbour search (default patchmatch: fastest; exact: reference)",
    )
    p.add_argument(
        "--example-preference",
        type=float,
        help="extra cost per rank of a selected example (e.g. 0.3): one coherent source "
        "per region instead of seams between examples of different colours (busts: faulty "
        "maps 25%% -> 8%%, but mean colour error up; default 0 as in the paper)",
    )
    p.add_argument(
        "--background",
        default="transparent",
        help="'transparent' (RGBA, default) or a colour: white, black, '#rrggbb'",
    )
    p.add_argument("--provenance", help="also write a picture of which example each region is from")
    p.add_argument(
        "--preview",
        help="also write the result rendered on its depth beside the best "
        "example's map on the same depth",
    )
    p.add_argument("--report", help="also write a JSON report (examples, timings, memory, target)")
    p.add_argument("--seed", type=int, default=0, help="random seed (same seed, same bytes)")
    add_mesh_options(p)  # mesh input and .glb/.obj output: imagemap/cli/batch.py
    add_common_options(p)
    p.set_defaults(func=run_synthesize)

    db = subparsers.add_parser("db", help="inspect a database of examples")
    db_sub = db.add_subparsers(dest="db_command", metavar="SUBCOMMAND")
    check = db_sub.add_parser(
        "check",
        help="read every example and report what was found",
        description="Read every NAME_depth/NAME_image pair of DIR and report sizes, depth "
        "ranges and problems (unpaired, unreadable or mismatched files). Exit code 1 when "
        "there is a problem.",
    )
    check.add_argument("directory")
    check.add_argument("--json", action="store_true", help="print the report as JSON")
    check.set_defaults(func=run_db_check)
    db.set_defaults(func=lambda args: db.print_help() or 2)


def parse_colour(text: str) -> tuple[float, float, float] | None:
    """'transparent' -> None; a named or '#rrggbb' colour -> RGB in [0, 1]."""
    named = {"white": "#ffffff", "black": "#000000", "grey": "#808080", "gray": "#808080"}
    text = named.get(text.lower(), text)
    if text.lower() == "transparent":
        return None
    if len(text) == 7 and text.startswith("#"):
        try:
            return tuple(int(text[i : i + 2], 16) / 255.0 for i in (1, 3, 5))
        except ValueError:
            pass
    raise InputError(f"--background: not a colour: {text!r} (use transparent, white or #rrggbb)")


def _name_of(depth_path) -> str:
    """``fish_008_depth.png`` -> ``fish_008``."""
    from pathlib import Path

    stem = Path(depth_path).stem
    return stem[: -len("_depth")] if stem.endswith("_depth") else stem


def _plan_outputs(args: argparse.Namespace) -> list[dict]:
    """One job per query depth: its output paths, checked before any work."""
    from pathlib import Path

    batch = len(args.depth) > 1
    for path in [p for p in (args.output, args.provenance, args.preview) if p]:
        if not batch and Path(path).suffix.lower() != ".png":
            raise InputError(f"{path}: output must be a .png")
        if batch and Path(path).suffix:
            raise InputError(f"{path}: with several depth maps, give a directory (no suffix)")
    if args.report and Path(args.report).suffix.lower() != ".json":
        raise InputError(f"{args.report}: --report must be a .json")
    names = [_name_of(p) for p in args.depth]
    if batch and len(set(names)) != len(names):
        raise InputError("several query depth maps have the same name")
    jobs = []
    for depth_path, name in zip(args.depth, names, strict=True):

        def place(target, kind, name=name):
            if not target:
                return None
            return Path(target) / f"{name}_{kind}.png" if batch else Path(target)

        jobs.append(
            {
                "depth": depth_path,
                "name": name,
                "output": place(args.output, "image"),
                "provenance": place(args.provenance, "provenance"),
                "preview": place(args.preview, "preview"),
            }
        )
    return jobs


def run_synthesize(args: argparse.Namespace) -> int:
    from imagemap.cli.batch import is_mesh_request, run_mesh_synthesize
    from imagemap.colorization import colorize
    from imagemap.database import Database
    from imagemap.io import atomic_path, read_depth, write_image
    from imagemap.progress import progress

    if is_mesh_request(args):  # a mesh in, or a textured mesh out
        return run_mesh_synthesize(args)
    background = parse_colour(args.background)
    jobs = _plan_outputs(args)
    # Bad input stops at the door, before any synthesis: every depth is read first.
    depths = [read_depth(job["depth"]) for job in jobs]
    database = Database.from_directory(args.db)
    if args.exclude:
        database = database.without(*[n.strip() for n in args.exclude.split(",")])
    examples = [n.strip() for n in args.examples.split(",")] if args.examples else None
    if examples:
        for name in examples:
            database[name]  # unknown names fail here, before any work
    interactive = not args.quiet and sys.stderr.isatty()
    reports = []
    for job, depth in progress(
        list(zip(jobs, depths, strict=True)), desc="maps", quiet=len(jobs) == 1 or not interactive
    ):
        tracemalloc.start()
        start = time.perf_counter()
        result = colorize(
            depth,
            database,
            preset=args.preset,
            m=args.m,
            examples=examples,
            backend=args.backend,
            example_preference=args.example_preference,
            seed=args.seed,
            quiet=len(jobs) > 1 or not interactive,
        )
        seconds = time.perf_counter() - start
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
        # Every output of a map is made before any is written: a failure leaves none.
        images = {
            job["output"]: result.rgba if background is None else result.on_background(background)
        }
        if job["provenance"]:
            images[job["provenance"]] = result.provenance
        if job["preview"]:
            images[job["preview"]] = _preview(depth, result, database)
        for path, picture in images.items():
            write_image(path, picture)
        reports.append(
            {
                "query": str(job["depth"]),
                "output": str(job["output"]),
                "examples": result.example_names,
                "seconds": seconds,
                "peak_traced_memory_mb": peak / 2**20,
                "timings": result.timings,
                "objective": result.objective,
                "preset": args.preset,
                "seed": args.seed,
            }
        )
        if not args.quiet:
            print(
                f"wrote {job['output']} ({depth.shape[1]}x{depth.shape[0]}) from "
                f"{', '.join(result.example_names)} in {seconds:.2f} s",
                file=sys.stderr,
            )
    if args.report:
        with atomic_path(args.report) as tmp:
            tmp.write_text(json.dumps(reports[0] if len(reports) == 1 else reports, indent=2))
    return 0


def _preview(depth, result, database):
    """The result on its depth beside the best example's map copied over (centroid-aligned)."""
    from imagemap.colorization import centroid_shift, translate
    from imagemap.render import preview_pair

    best = database[result.example_names[0]]
    shift = centroid_shift(best.mask, depth > 0)
    reference = translate(best.image, shift, depth.shape)
    reference_mask = translate(best.mask.astype("float32"), shift, depth.shape) > 0.5
    return preview_pair(depth, result.image, reference, reference_mask=reference_mask)


def run_db_check(args: argparse.Namespace) -> int:
    from imagemap.database import check_database

    rows, problems = check_database(args.directory)
    if args.json:
        print(json.dumps({"examples": rows, "problems": problems}, indent=2))
    else:
        print(f"{args.directory}: {len(rows)} readable example(s)")
        for row in rows:
            print(
                f"  {row['name']:<24} {row['size']:>9}  depth {row['depth_min']:.3f}-"
                f"{row['depth_max']:.3f}  foreground {100 * row['foreground']:.0f}%"
                f"{'  labels' if row['labels'] else ''}{'  json' if row['json'] else ''}"
            )
        for problem in problems:
            print(f"  problem: {problem}")
    return 1 if problems else 0
