"""``imagemap synthesize`` and ``imagemap db check``."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from imagemap.cli import PRESET_NAMES, add_common_options, map_large_blocks
from imagemap.cli.mesh import is_mesh_request, run_mesh_synthesize
from imagemap.cli.options import (
    add_config_options,
    add_mesh_options,
    config_options,
    parse_colour,
)
from imagemap.errors import InputError
from imagemap.progress import progress

#: Why the command functions import inside themselves (tests/test_imports_marked.py):
#: the parser is built without NumPy, SciPy or numba, so ``imagemap --help`` answers at
#: once; each command imports what it needs when it runs.
DEFERRED_IMPORTS = "start-up: building the parser loads no scientific module"

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
        choices=PRESET_NAMES,
        default="busts",
        help="class preset: weights, patch sizes and m after the paper's Table 1 (default busts)",
    )
    add_config_options(p)
    p.add_argument("--examples", help="comma-separated example names to use instead")
    p.add_argument("--exclude", help="comma-separated example names to leave out of the database")
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
    p.add_argument(
        "--no-maps",
        action="store_true",
        help="write the colour only: by default the examples' PBR maps (NAME_normal.png, "
        "_roughness, _metallic, _height, _ao) are carried through the same source map and "
        "written beside the output (out.png -> out_roughness.png, ...)",
    )
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="allow replacing an existing NAME_image.png, NAME_labels.png or NAME.json that "
        "has a NAME_depth.* or a NAME mesh beside it (a held-out truth, or an example of a "
        "database this command does not read); nothing else: never a PBR map "
        "(NAME_roughness.png ...), a depth map, a query or a file of --db",
    )
    p.add_argument(
        "--no-memory-check",
        action="store_true",
        help="run even when the estimated memory exceeds what is available (see -v for the "
        "estimate)",
    )
    before = {action.dest for action in p._actions}
    # Mesh input and .glb/.obj output: imagemap/cli/mesh.py.
    add_mesh_options(p, uv_space=True, fine_views=True)
    MESH_FLAGS.update(
        {a.dest: "/".join(a.option_strings) for a in p._actions if a.dest not in before}
    )
    add_common_options(p)
    p.set_defaults(func=run_synthesize)

    db = subparsers.add_parser("db", help="inspect a database of examples")
    db_sub = db.add_subparsers(dest="db_command", metavar="SUBCOMMAND")
    check = db_sub.add_parser(
        "check",
        help="read every example and report what was found",
        description="Read every NAME_depth/NAME_image pair and every textured mesh of DIR "
        "(rendered from the front at 200x150, as imagemap synthesize sees them by default) "
        "and report sizes, depth ranges and problems (unpaired, unreadable or mismatched "
        "files, meshes with nothing visible or no colours). Exit code 1 when there is a "
        "problem.",
    )
    check.add_argument("directory")
    check.add_argument("--json", action="store_true", help="print the report as JSON")
    check.set_defaults(func=run_db_check)
    db.set_defaults(func=lambda args: db.print_help() or 2)


#: The mesh options (``add_mesh_options``: destination -> flags), filled when the parser is
#: built: on depth-map input each is refused, not ignored.
MESH_FLAGS: dict[str, str] = {}


def check_applicable(args: argparse.Namespace, mesh: bool) -> None:
    """Refuse options that do not apply to the input, and options that conflict.

    ``args.given`` holds the options the command line gave (see ``imagemap.cli``); a
    Namespace built elsewhere, without it, is checked for conflicts only.
    """
    given: frozenset[str] = getattr(args, "given", frozenset())
    if not mesh:
        for dest, flags in MESH_FLAGS.items():
            if dest in given:
                raise InputError(
                    f"{flags}: applies to mesh input (.glb .obj .ply ...); "
                    f"{args.depth[0]} is a depth map (its size is its own)"
                )
    check_views_given(args)
    for option, text in (("--examples", args.examples), ("--exclude", args.exclude)):
        if text is not None and not [n for n in text.split(",") if n.strip()]:
            raise InputError(f"{option} {text!r}: no example name given")
    if args.examples and args.exclude:
        both = {n.strip() for n in args.examples.split(",")} & {
            n.strip() for n in args.exclude.split(",")
        }
        if both:
            raise InputError(
                f"--examples and --exclude both name {', '.join(sorted(both))}: "
                "an example cannot be used and left out"
            )
    if args.examples:
        names = [n.strip() for n in args.examples.split(",") if n.strip()]
        if len(set(names)) != len(names):
            raise InputError(f"--examples {args.examples!r}: a name is given twice")
    output = Path(args.output).suffix.lower()
    if mesh and "background" in given and output in (".glb", ".obj"):
        raise InputError(
            f"--background: applies to .png maps; {args.output} is a textured mesh "
            "(its texture has no background)"
        )


def check_cache() -> None:
    """``IMAGEMAP_CACHE`` (where mesh examples' renders are kept), when set, must be a folder
    this process can read and write, or one it can make: said at the door, not as a
    traceback from the first mesh example."""
    import os

    root = os.environ.get("IMAGEMAP_CACHE")
    if not root:
        return
    path = Path(root).expanduser()
    existing = path
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if existing == path and not path.is_dir():
        raise InputError(f"IMAGEMAP_CACHE={root}: is a file, not a folder")
    if not existing.is_dir():
        raise InputError(f"IMAGEMAP_CACHE={root}: {existing} is a file, not a folder")
    if not os.access(existing, os.R_OK | os.W_OK | os.X_OK):
        raise InputError(
            f"IMAGEMAP_CACHE={root}: {existing} cannot be read and written by this user; "
            "point IMAGEMAP_CACHE at a folder you own (or unset it)"
        )


def check_views_given(args: argparse.Namespace) -> None:
    """--view beside --views (in either order) is a conflict; an empty one is an error."""
    given: frozenset[str] = getattr(args, "given", frozenset())
    if "view" in given and "views" in given:
        raise InputError("--view and --views: give one (--view AZ,EL is --views AZ,EL)")
    for dest, option in (("view", "--view"), ("views", "--views")):
        value = getattr(args, dest, None)
        if (dest in given or value is not None) and isinstance(value, str) and not value.strip():
            raise InputError(f"{option} '': no view given (e.g. {option} front, or 30,10)")


def _name_of(depth_path) -> str:
    """``fish_008_depth.png`` -> ``fish_008``."""
    stem = Path(depth_path).stem
    return stem[: -len("_depth")] if stem.endswith("_depth") else stem


def _plan_outputs(args: argparse.Namespace) -> list[dict]:
    """One job per query depth with its output paths (suffixes and kinds checked here;
    clashes and writability by :func:`_check_outputs` once the database is open)."""
    batch = len(args.depth) > 1
    options = [("-o", args.output), ("--provenance", args.provenance), ("--preview", args.preview)]
    for option, path in options:
        if not path:
            continue
        if not batch and Path(path).is_dir():
            raise InputError(
                f"{path}: {option} is a directory; give a file name such as "
                f"{Path(path) / 'map.png'} (a directory is for several depth maps)"
            )
        if not batch and Path(path).suffix.lower() != ".png":
            raise InputError(
                f"{path}: {option} is written as a .png file; give a name ending in .png"
            )
        if batch and Path(path).exists() and not Path(path).is_dir():
            raise InputError(
                f"{path}: with several depth maps {option} names a directory, "
                "but this is an existing file"
            )
        if batch and Path(path).suffix and not Path(path).is_dir():
            raise InputError(f"{path}: with several depth maps, give a directory (no suffix)")
    if args.report and Path(args.report).suffix.lower() != ".json":
        raise InputError(f"{args.report}: --report is written as .json")
    names = [_name_of(p) for p in args.depth]
    if batch and len(set(names)) != len(names):
        duplicates = sorted({n for n in names if names.count(n) > 1})
        raise InputError(f"several query depth maps have the same name: {', '.join(duplicates)}")
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


def _check_outputs(args: argparse.Namespace, jobs: list[dict], database) -> None:
    """Every output against every input and every other output, and writable: before any work."""
    from imagemap.outputs import OutputPlan, check_output_directory

    plan = OutputPlan(overwrite=args.overwrite)
    for job in jobs:
        # The query, and the truth beside it (NAME_image.png ...): --overwrite replaces that.
        plan.add_query(
            job["depth"],
            "query depth",
            overwrite=args.overwrite,
            hint="; --overwrite replaces it",
        )
    plan.add_database(database, args.db)
    if len(jobs) > 1:
        for option, folder in (
            ("-o", args.output),
            ("--provenance", args.provenance),
            ("--preview", args.preview),
        ):
            if folder:
                check_output_directory(folder, f"{option} directory")
    for job in jobs:
        for key, option in (
            ("output", "-o"),
            ("provenance", "--provenance"),
            ("preview", "--preview"),
        ):
            if job[key]:
                plan.add_output(job[key], option, suffixes=(".png",))
    # PBR maps beside each map: every kind an example that may be used has.
    from imagemap.materials import companion_path, database_map_kinds

    names = [n.strip() for n in args.examples.split(",") if n.strip()] if args.examples else None
    kinds = [] if getattr(args, "no_maps", False) else database_map_kinds(database, names)
    for job in jobs:
        if len(jobs) > 1:
            job["maps"] = {k: job["output"].with_name(f"{job['name']}_{k}.png") for k in kinds}
        else:
            job["maps"] = {k: companion_path(job["output"], k) for k in kinds}
        for kind, path in job["maps"].items():
            plan.add_companion(path, job["output"], f"{kind} map beside -o")
    if args.report:
        plan.add_output(args.report, "--report", suffixes=(".json",))
    plan.check()


def run_synthesize(args: argparse.Namespace) -> int:
    from imagemap.database import Database
    from imagemap.depth.budget import guard_colorize
    from imagemap.depth.config import resolve_config
    from imagemap.io import read_depth

    mesh = is_mesh_request(args)  # a mesh in, or a textured mesh out
    check_applicable(args, mesh)
    check_cache()
    if mesh:
        map_large_blocks(args)
        return run_mesh_synthesize(args)
    background = parse_colour(args.background)
    config = resolve_config(args.preset, **config_options(args))  # a bad combination stops here
    jobs = _plan_outputs(args)
    # Bad input stops at the door, before any synthesis: every depth is read first.
    depths = [read_depth(job["depth"]) for job in jobs]
    map_large_blocks(args, max(depth.size for depth in depths))
    # One query: the examples' arrays are dropped once it has posed them (a batch keeps
    # them for the next query's selection).
    database = Database.from_directory(args.db, keep_arrays=len(jobs) > 1)
    if args.exclude:
        database = database.without([n.strip() for n in args.exclude.split(",") if n.strip()])
    examples = [n.strip() for n in args.examples.split(",") if n.strip()] if args.examples else None
    if examples:
        for name in examples:
            database[name]  # unknown names fail here, before any work
    _check_outputs(args, jobs, database)
    for job, depth in zip(jobs, depths, strict=True):
        guard_colorize(
            depth,
            database,
            config,
            examples=examples,
            what=str(job["depth"]),
            check=not args.no_memory_check,
        )
    interactive = not args.quiet and sys.stderr.isatty()
    batch = len(jobs) > 1
    reports, failures = [], []
    try:
        for job, depth in progress(
            list(zip(jobs, depths, strict=True)), desc="maps", quiet=not batch or not interactive
        ):
            try:
                report = _synthesize_one(
                    args, job, depth, database, config, examples, background, batch
                )
            except KeyboardInterrupt:
                raise
            except Exception as exc:
                if not batch:
                    raise
                failures.append({"query": str(job["depth"]), "error": str(exc)})
                print(f"imagemap: {job['depth']}: failed: {exc}", file=sys.stderr)
                continue
            reports.append(report)
    except KeyboardInterrupt:
        if batch:
            print(
                f"imagemap: interrupted: {len(reports)} of {len(jobs)} maps written "
                f"({', '.join(r['output'] for r in reports) or 'none'}); no partial file left",
                file=sys.stderr,
            )
            _write_batch_report(args, reports, failures, interrupted=True)
        raise
    if batch:
        _write_batch_report(args, reports, failures)
        if not args.quiet or failures:
            print(
                f"imagemap: {len(reports)} of {len(jobs)} maps written to {args.output}"
                + (f"; failed: {', '.join(f['query'] for f in failures)}" if failures else ""),
                file=sys.stderr,
            )
    return 1 if failures else 0


def _synthesize_one(args, job, depth, database, config, examples, background, batch) -> dict:
    """One map: synthesize, build every output, write them all-or-nothing."""
    from imagemap.depth.budget import memory_check
    from imagemap.depth.pipeline import colorize
    from imagemap.io import image_writer
    from imagemap.outputs import write_all

    interactive = not args.quiet and sys.stderr.isatty()
    start = time.perf_counter()
    # No tracemalloc here: tracing every allocation (numba loading its cached kernels
    # makes many) cost about 1.5 s and 16 MB of a 200x150 run.
    with memory_check(False):  # checked before any work, for every map
        result = colorize(
            depth,
            database,
            preset=config,
            examples=examples,
            seed=args.seed,
            quiet=batch or not interactive,
        )
    seconds = time.perf_counter() - start
    # Every output of a map is made before any is written, and written as a set:
    # a failure leaves none of them.
    picture = result.rgba if background is None else result.on_background(background)
    writers = {job["output"]: image_writer(picture)}
    del picture  # converted for writing: the float copy is not held through the maps below
    if job["provenance"]:
        writers[job["provenance"]] = image_writer(result.provenance)
    if job["preview"]:
        writers[job["preview"]] = image_writer(_preview(depth, result, database))
    if job.get("maps"):
        from imagemap.materials import maps_written

        # A kind none of the examples used has would be its neutral value everywhere: a
        # constant map says nothing, so it is not written, and the user is told.
        maps, missing = maps_written(result, database, list(job["maps"]))
        if missing and not args.quiet:
            print(
                f"imagemap: note: no {', '.join(missing)} map written beside {job['output']}: "
                f"the examples used ({', '.join(result.example_names)}) have none (it would "
                "be a constant)",
                file=sys.stderr,
            )
        for kind, array in maps.items():
            writers[job["maps"][kind]] = image_writer(array, bits=16 if kind == "height" else 8)
    report = {
        "query": str(job["depth"]),
        "output": str(job["output"]),
        "examples": result.example_names,
        "seconds": seconds,
        "peak_rss_mb": _peak_rss_mb(),
        "timings": result.timings,
        "stages": [
            {"name": r.name, "seconds": round(r.seconds, 4), "changed": r.changed}
            for r in result.stages
        ],
        "options": config_options(args),
        "objective": result.objective,
        "preset": args.preset,
        "seed": args.seed,
    }
    if args.report and not batch:
        writers[Path(args.report)] = _json_writer(report)
    write_all(writers)
    if not args.quiet:
        print(
            f"wrote {job['output']} ({depth.shape[1]}x{depth.shape[0]}) from "
            f"{', '.join(result.example_names)} in {seconds:.2f} s",
            file=sys.stderr,
        )
    return report


def _peak_rss_mb() -> float | None:
    """The process's peak resident memory so far (MB; None where it cannot be read)."""
    try:
        with open("/proc/self/status") as status:
            for line in status:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    try:
        import resource  # deferred: optional dependency (not on Windows: ImportError below)

        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        return peak / 2**20 if sys.platform == "darwin" else peak / 1024.0  # bytes / KiB
    except (ImportError, OSError):
        return None


def _json_writer(content):
    import json

    text = json.dumps(content, indent=2)

    def write(tmp) -> None:
        Path(tmp).write_text(text)

    return write


def _write_batch_report(args, reports, failures, interrupted: bool = False) -> None:
    """The batch's report: one entry per query, in order; a failed one has an "error"."""
    from imagemap.outputs import write_all

    if not args.report:
        return
    entries = reports + failures
    order = {str(p): i for i, p in enumerate(args.depth)}
    entries.sort(key=lambda entry: order.get(entry["query"], len(order)))
    if interrupted:
        entries.append({"interrupted": True})
    write_all({Path(args.report): _json_writer(entries)})


def _preview(depth, result, database):
    """The result on its depth beside the best example's map copied over (centroid-aligned)."""
    from imagemap.align import translate_masked
    from imagemap.render import preview_pair

    best = database[result.example_names[0]]
    reference, reference_mask = translate_masked(best.image, best.mask, depth > 0)
    return preview_pair(depth, result.image, reference, reference_mask=reference_mask)


def run_db_check(args: argparse.Namespace) -> int:
    import json

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
                f"{'' if row['source'] == 'images' else '  mesh ' + row['source']}"
            )
        for problem in problems:
            print(f"  problem: {problem}")
    return 1 if problems else 0
