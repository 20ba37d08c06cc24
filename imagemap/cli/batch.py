"""``imagemap batch`` and the mesh options of ``imagemap synthesize``."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from imagemap.errors import InputError
from imagemap.validate import (
    fraction,
    non_negative_float,
    non_negative_int,
    parse_size,
    positive_int,
)

BATCH_HELP = """\
Synthesize every depth map (NAME_depth.png|tif|tiff|npy -> NAME_image.png) and
every mesh (.glb .obj .ply .stl .off -> textured NAME.glb, or .obj with --format obj)
of INPUT_DIR into OUT_DIR.

The database is prepared once (examples loaded; mesh examples rendered at each
view, cached on disk) and shipped once to each worker. Runs on a local process
pool (--workers N, nothing to start) or on an existing Dask cluster (--scheduler;
pip install 'imagemap[dask]'). Resumable: objects whose outputs are complete (same
input, options and imagemap engine) are skipped (--force redoes them); every output
is written atomically; a failing object is reported and the rest go on (exit code 1
if any failed). Prints a summary: done, skipped, failed, objects per minute;
OUT_DIR/batch_report.json has the details.

examples:
  python -m data_gen fish --count 12 --holdout 3 --meshes --out fish
  imagemap batch fish/holdout/meshes --db fish/meshes -o textured/ --preset fish --workers 2

  # on a Dask cluster (see the README): dask scheduler; dask worker tcp://HOST:8786
  imagemap batch crowd/ --db humans/ -o maps/ --preset humans --scheduler tcp://HOST:8786

  # four views baked into one UV atlas per mesh, OBJ + MTL + PNG
  imagemap batch busts/ --db bust_meshes/ -o out/ --views front,back,left,right --format obj
"""


def add_mesh_options(parser: argparse.ArgumentParser) -> None:
    """--view, --views, --size, --texture-size: how meshes are seen and textured."""
    group = parser.add_argument_group("meshes (input .glb .obj .ply ...; output .glb or .obj)")
    group.add_argument(
        "--view",
        help="AZ,EL in degrees to look from (default front, 0,0: along -z as data_gen); "
        "a negative value needs '=': --view=-90,0",
    )
    group.add_argument(
        "--views",
        help="several views baked into one UV atlas: names (front,back,left,right,top,"
        "bottom) or AZ,EL pairs, e.g. 'front,back' or '0,0;90,0;180,0'",
    )
    group.add_argument(
        "--size",
        type=parse_size,
        default=(200, 150),
        help="WIDTHxHEIGHT of each view's depth map (default 200x150)",
    )
    group.add_argument(
        "--texture-size",
        type=positive_int,
        default=512,
        help="texture width and height when several views are baked (default 512)",
    )


def add_colorize_options(parser: argparse.ArgumentParser) -> None:
    """--m, --backend, --example-preference, --edge-support, --no-feature-completion,
    --even-palettes and --seed: one definition for ``imagemap synthesize`` and
    ``imagemap batch``, so their checks cannot drift apart."""
    from imagemap.cli import BACKEND_NAMES

    parser.add_argument(
        "--m", type=positive_int, help="number of examples to select automatically (>= 1)"
    )
    parser.add_argument(
        "--backend",
        choices=BACKEND_NAMES,
        help="nearest-neighbour search (default patchmatch: fastest; exact: reference)",
    )
    parser.add_argument(
        "--example-preference",
        type=non_negative_float,
        help="extra cost per rank of a selected example at the coarser levels (default "
        "0.3): each region of the object from one example where it fits nearly as well, "
        "instead of patches of two palettes; 0 is the paper's method",
    )
    parser.add_argument(
        "--edge-support",
        type=fraction,
        help="where the copy changes source inside one example and the step there is an "
        "edge the voted map shows too (a sleeve meeting a hand), keep it one pixel sharp "
        "if the vote shows at least this share of it (default 0.3); 0 blends every seam "
        "(softer part boundaries)",
    )
    parser.add_argument(
        "--no-feature-completion",
        dest="complete_features",
        action="store_const",
        const=False,
        default=None,
        help="leave an example's eye, lips or brow as the copy cut it (by default a small "
        "feature copied only in part, say lips cut into a lozenge where two offsets meet, "
        "is copied whole)",
    )
    parser.add_argument(
        "--even-palettes",
        dest="even_palettes",
        action="store_const",
        const=True,
        default=None,
        help="where the map shows one part (a face's skin, a plain shirt) in two examples' "
        "colours, shift the smaller share into the larger's: one skin tone from face to neck "
        "(off by default; docs/presets.md)",
    )
    parser.add_argument(
        "--seed", type=non_negative_int, default=0, help="random seed >= 0 (same seed, same bytes)"
    )


def views_of(args: argparse.Namespace):
    from imagemap.mesh import FRONT, parse_view, parse_views

    if getattr(args, "views", None):
        return tuple(parse_views(args.views))
    if getattr(args, "view", None):
        return (parse_view(args.view),)
    return (FRONT,)


# ------------------------------------------------------------- synthesize hook


def is_mesh_request(args: argparse.Namespace) -> bool:
    """Whether ``imagemap synthesize`` was given a mesh or asked for a textured mesh."""
    from imagemap.mesh import TEXTURED_SUFFIXES, is_mesh_path

    return any(is_mesh_path(p) for p in args.depth) or (
        Path(args.output).suffix.lower() in TEXTURED_SUFFIXES
    )


def run_mesh_synthesize(args: argparse.Namespace) -> int:
    """``imagemap synthesize MESH -o out.glb|out.obj|out.png``: one mesh, one or more views."""
    import time

    from imagemap.cli.synthesize import parse_colour
    from imagemap.database import Database
    from imagemap.io import atomic_path, write_image
    from imagemap.mesh import (
        TEXTURED_SUFFIXES,
        colorize_mesh,
        export_textured,
        is_mesh_path,
        load_mesh,
    )

    output = Path(args.output)
    if len(args.depth) > 1:
        raise InputError(
            "several inputs with a mesh among them: put them in a folder and use "
            "'imagemap batch DIR --db DB -o OUTDIR'"
        )
    source = Path(args.depth[0])
    if not is_mesh_path(source):
        raise InputError(
            f"{output}: a textured mesh (.glb, .obj) needs a mesh input; {source} is not one"
        )
    if output.suffix.lower() not in (*TEXTURED_SUFFIXES, ".png"):
        raise InputError(f"{output}: output must be a .glb, .obj (textured mesh) or .png (map)")
    if args.preview:
        raise InputError("--preview is for depth-map inputs")
    for path in (args.provenance,):
        if path and Path(path).suffix.lower() != ".png":
            raise InputError(f"{path}: output must be a .png")
    if args.report and Path(args.report).suffix.lower() != ".json":
        raise InputError(f"{args.report}: --report must be a .json")
    background = parse_colour(args.background)
    views = views_of(args)
    mesh = load_mesh(source)  # bad input stops here, before any work
    database = Database.from_directory(args.db, view=views[0], size=args.size)
    if args.exclude:
        database = database.without(*[n.strip() for n in args.exclude.split(",")])
    examples = [n.strip() for n in args.examples.split(",")] if args.examples else None
    for name in examples or []:
        database[name]  # unknown names fail here
    start = time.perf_counter()
    made = colorize_mesh(
        mesh,
        database,
        list(views),
        size=args.size,
        texture_size=args.texture_size,
        preset=args.preset,
        seed=args.seed,
        m=args.m,
        examples=examples,
        backend=args.backend,
        example_preference=args.example_preference,
        edge_support=args.edge_support,
        complete_features=args.complete_features,
        even_palettes=args.even_palettes,
        quiet=args.quiet or not sys.stderr.isatty(),
    )
    seconds = time.perf_counter() - start
    first = made.results[0]
    if output.suffix.lower() == ".png":
        write_image(output, first.rgba if background is None else first.on_background(background))
    else:
        export_textured(made.mesh, output)
    if args.provenance:
        write_image(args.provenance, first.provenance)
    if args.report:
        report = {
            "query": str(source),
            "output": str(output),
            "views": [str(v) for v in views],
            "examples": [r.example_names for r in made.results],
            "seconds": seconds,
            "preset": args.preset,
            "seed": args.seed,
        }
        with atomic_path(args.report) as tmp:
            tmp.write_text(json.dumps(report, indent=2))
    if not args.quiet:
        print(
            f"wrote {output} from {len(views)} view(s) of {source.name} in {seconds:.2f} s",
            file=sys.stderr,
        )
    return 0


# ------------------------------------------------------------------------ batch


def register(subparsers: argparse._SubParsersAction) -> None:
    from imagemap.cli import PRESET_NAMES, add_common_options

    p = subparsers.add_parser(
        "batch",
        help="synthesize every depth map and mesh of a folder (local pool or Dask)",
        description=BATCH_HELP,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("input_dir", metavar="INPUT_DIR", help="folder of depth maps and/or meshes")
    p.add_argument("--db", required=True, help="database directory (pictures and/or meshes)")
    p.add_argument("-o", "--output", required=True, help="output directory")
    p.add_argument(
        "--workers",
        type=positive_int,
        default=1,
        help="local worker processes >= 1 (default 1: in-process)",
    )
    p.add_argument(
        "--scheduler",
        help="address of a Dask scheduler (tcp://host:8786): run there instead of locally",
    )
    p.add_argument(
        "--preset",
        choices=sorted(PRESET_NAMES),
        default="busts",
        help="class preset (default busts)",
    )
    add_colorize_options(p)
    p.add_argument(
        "--format", choices=("glb", "obj"), default="glb", help="textured mesh format (glb)"
    )
    p.add_argument(
        "--background",
        default="transparent",
        help="maps of depth inputs: 'transparent' (RGBA, default) or a colour",
    )
    p.add_argument("--force", action="store_true", help="redo objects already complete")
    add_mesh_options(p)
    add_common_options(p)
    p.set_defaults(func=run_batch_cli)


def run_batch_cli(args: argparse.Namespace) -> int:
    from imagemap.batch import BatchOptions, run_batch
    from imagemap.cli.synthesize import parse_colour

    options = BatchOptions(
        preset=args.preset,
        m=args.m,
        backend=args.backend,
        example_preference=args.example_preference,
        edge_support=args.edge_support,
        complete_features=args.complete_features,
        even_palettes=args.even_palettes,
        seed=args.seed,
        views=views_of(args),
        size=args.size,
        texture_size=args.texture_size,
        mesh_format=args.format,
        background=parse_colour(args.background),
    )
    if args.scheduler and not args.scheduler.startswith(("tcp://", "tls://", "inproc://")):
        raise InputError(f"--scheduler {args.scheduler!r}: expected tcp://HOST:PORT")
    summary = run_batch(
        args.input_dir,
        args.db,
        args.output,
        options,
        workers=args.workers,
        scheduler=args.scheduler,
        force=args.force,
        quiet=args.quiet,
    )
    if not args.quiet:
        print(f"batch: {summary.line()}", file=sys.stderr)
    return 1 if summary.failed else 0
