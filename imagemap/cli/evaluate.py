"""``imagemap evaluate``: leave-one-out evaluation with baselines and a static report."""

from __future__ import annotations

import argparse
import math
import sys

from imagemap.cli import METHOD_NAMES, PRESET_NAMES, add_common_options
from imagemap.cli.options import add_config_options, config_options
from imagemap.errors import InputError
from imagemap.validate import positive_int

#: Why the command functions import inside themselves (tests/test_imports_marked.py):
#: the parser is built without NumPy, SciPy or numba, so ``imagemap --help`` answers at
#: once; each command imports what it needs when it runs.
DEFERRED_IMPORTS = "start-up: building the parser loads no scientific module"

EVALUATE_HELP = """\
Leave-one-out evaluation of a database: every object's image-map is synthesized
from the other objects only (automatic example selection, the class preset) and
compared with its true image-map over the object's mask, for the full method and
six baselines:

  full          the method (pyramid, hard EM, depth + colour + position)
  copy_nearest  the nearest example's map pasted at the query's centroid
  warp_nearest  the first-choice example posed and warped onto the query as the
                method does, and copied whole (no synthesis)
  one_pass      one pass of depth-only matching and voting (no EM, no position)
  mean_vote     the full method with the paper's mean vote instead of the seam-
                blended copy
  no_position   the full method without the position term
  laplacian     the full method on the paper's Laplacian colour bands instead
                of each pyramid level's plain colours
  paper         the paper's method on our guide bands (--finish paper: mean
                vote on Laplacian colour bands, no finishing stage)

Writes REPORT_DIR/results.csv (object, method, ciede2000, ssim, part_accuracy,
part_transfer, ..., blur_ratio, the coherence measures fragments_90, fragment_share,
seam_length, continuity, midtone_ratio, parts_one_palette, parts_palette_measured
(docs/measures.md), faulty, seconds), summary.md (per class: the means, a coherence
table, their 95 % bootstrap intervals over the objects, and each method's paired
difference to the first method), index.html (static; open it in a browser) with
its pictures under images/, and overview.png.
An object whose synthesis fails is named (exit code 1) and the others go on;
Ctrl-C stops the run and still writes the report of the objects finished.

examples:
  python -m data_gen fish --count 12 --seed 0 --out fish_db
  imagemap evaluate fish_db --out fish_report --workers 2
  imagemap evaluate busts_db --out quick --methods full,copy_nearest --limit 3
"""


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "evaluate",
        help="leave-one-out evaluation of a database against baselines, with an HTML report",
        description=EVALUATE_HELP,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("db", metavar="DB_DIR", help="database directory (NAME_depth/NAME_image pairs)")
    p.add_argument("--out", required=True, metavar="REPORT_DIR", help="report directory")
    p.add_argument(
        "--preset",
        choices=PRESET_NAMES,
        help="class preset (default: the preset named like each object's class, else busts)",
    )
    p.add_argument("--workers", type=positive_int, default=1, help="processes (default 1)")
    p.add_argument(
        "--methods",
        default=",".join(METHOD_NAMES),
        help=f"comma-separated methods (default all: {','.join(METHOD_NAMES)})",
    )
    p.add_argument("--limit", type=positive_int, help="evaluate only the first N objects")
    add_config_options(p)  # applied to each class's preset; the methods derive from it
    add_common_options(p)
    p.set_defaults(func=run_evaluate)


def run_evaluate(args: argparse.Namespace) -> int:
    from imagemap.database import Database
    from imagemap.depth.config import resolve_config
    from imagemap.evaluation import METHODS, leave_one_out
    from imagemap.outputs import check_output_directory, resolve
    from imagemap.report import check_report, summarize, write_report

    options = config_options(args)
    resolve_config(args.preset, **options)  # a bad option or combination stops here
    database = Database.from_directory(args.db)
    methods = tuple(m.strip() for m in args.methods.split(",") if m.strip())
    unknown = [m for m in methods if m not in METHODS]
    if unknown or not methods:
        raise InputError(
            f"--methods: unknown method(s) {', '.join(unknown) or '(none given)'}; "
            f"use some of {', '.join(METHODS)}"
        )
    twice = sorted({m for m in methods if methods.count(m) > 1})
    if twice:
        raise InputError(f"--methods: {', '.join(twice)} given twice (one row per method)")
    if resolve(args.out) == resolve(args.db):
        raise InputError(f"{args.out}: --out is the database {args.db}; give another directory")
    check_output_directory(args.out, "--out report directory")
    evaluation = leave_one_out(
        database,
        preset=args.preset,
        methods=methods,
        workers=args.workers,
        limit=args.limit,
        seed=args.seed,
        quiet=args.quiet,
        options=options,
    )
    paths = write_report(evaluation, args.out)
    missing = check_report(args.out)
    if missing:
        print(f"imagemap: report links missing files: {', '.join(missing)}", file=sys.stderr)
        return 1
    if not args.quiet:
        table = summarize(evaluation)
        for class_name, rows in table.items():
            parts = []
            for method, row in rows.items():
                text = f"{method} ΔE00 {row['ciede2000']:.1f}"
                if not math.isnan(row["part_accuracy"]):
                    text += f" part {row['part_accuracy']:.2f}"
                parts.append(f"{text} faulty {100 * row['faulty']:.0f}%")
            print(f"{class_name}: " + "; ".join(parts))
        print(
            f"evaluated {len(evaluation.objects)} objects x {len(methods)} methods in "
            f"{evaluation.seconds:.0f} s with {args.workers} worker(s); report {paths['html']}"
        )
    for name, message in evaluation.failed:
        print(f"imagemap: {name}: failed: {message}", file=sys.stderr)
    if evaluation.failed:
        print(
            f"imagemap: {len(evaluation.objects)} object(s) evaluated, "
            f"{len(evaluation.failed)} failed",
            file=sys.stderr,
        )
    if evaluation.interrupted:
        print(
            f"imagemap: report of the {len(evaluation.objects)} object(s) evaluated before "
            f"the interruption written to {paths['html']}",
            file=sys.stderr,
        )
        return 130
    return 1 if evaluation.failed else 0
