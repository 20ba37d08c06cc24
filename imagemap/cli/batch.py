"""``imagemap batch``."""

from __future__ import annotations

import argparse
import sys

from imagemap.cli import PRESET_NAMES, add_common_options
from imagemap.cli.options import (
    add_config_options,
    add_mesh_options,
    config_options,
    parse_colour,
    views_of,
)
from imagemap.errors import InputError
from imagemap.validate import positive_int

#: Why the command functions import inside themselves (tests/test_imports_marked.py):
#: the parser is built without NumPy, SciPy or numba, so ``imagemap --help`` answers at
#: once; each command imports what it needs when it runs.
DEFERRED_IMPORTS = "start-up: building the parser loads no scientific module"

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


# ------------------------------------------------------------------------ batch


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "batch",
        help="synthesize every depth map and mesh of a folder (local pool or Dask)",
        description=BATCH_HELP,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("input_dir", metavar="INPUT_DIR", help="folder of depth maps and/or meshes")
    p.add_argument("--db", required=True, help="database directory (pictures and/or meshes)")
    p.add_argument("-o", "--output", required=True, help="output directory")
    where = p.add_mutually_exclusive_group()  # a local pool or a cluster, not both
    where.add_argument(
        "--workers",
        type=positive_int,
        default=1,
        help="local worker processes >= 1 (default 1: in-process)",
    )
    where.add_argument(
        "--scheduler",
        help="address of a Dask scheduler (tcp://host:8786): run there instead of locally",
    )
    p.add_argument(
        "--preset",
        choices=sorted(PRESET_NAMES),
        default="busts",
        help="class preset (default busts)",
    )
    add_config_options(p)
    p.add_argument(
        "--format", choices=("glb", "obj"), default="glb", help="textured mesh format (glb)"
    )
    p.add_argument(
        "--background",
        default="transparent",
        help="maps of depth inputs: 'transparent' (RGBA, default) or a colour",
    )
    p.add_argument("--force", action="store_true", help="redo objects already complete")
    p.add_argument(
        "--no-maps",
        action="store_true",
        help="write the colour only: by default the examples' PBR maps are carried as "
        "imagemap synthesize carries them (depth maps: NAME_normal.png, _roughness ... beside "
        "NAME_image.png; meshes: in the GLB's material)",
    )
    add_mesh_options(p, uv_space=True, fine_views=True)  # --size: each mesh's, as synthesize
    add_common_options(p)
    p.set_defaults(func=run_batch_cli)


def run_batch_cli(args: argparse.Namespace) -> int:
    from imagemap.batch import BatchOptions, run_batch
    from imagemap.cli.synthesize import check_cache, check_views_given
    from imagemap.scene.files import unit_scale

    check_views_given(args)
    check_cache()
    # The same options as imagemap synthesize's, read the same way (imagemap.mesh.route).
    options = BatchOptions(
        preset=args.preset,
        options=config_options(args),
        seed=args.seed,
        views=views_of(args),
        size=args.size,
        texture_size=args.texture_size,
        mesh_format=args.format,
        background=parse_colour(args.background),
        auto_views=getattr(args, "views", None) == "auto",
        scale=unit_scale(args.units, args.scale),
        uv_space=args.uv_space,
        registered=args.registered,
        maps=not args.no_maps,
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
