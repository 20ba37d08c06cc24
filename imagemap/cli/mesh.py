"""The mesh route of ``imagemap synthesize``: a mesh in, a textured mesh (or its map) out."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from imagemap.errors import InputError

__all__ = ["is_mesh_request", "run_mesh_synthesize"]


def is_mesh_request(args: argparse.Namespace) -> bool:
    """Whether ``imagemap synthesize`` was given a mesh or asked for a textured mesh."""
    from imagemap.mesh import TEXTURED_SUFFIXES, is_mesh_path

    return any(is_mesh_path(p) for p in args.depth) or (
        Path(args.output).suffix.lower() in TEXTURED_SUFFIXES
    )


def run_mesh_synthesize(args: argparse.Namespace) -> int:
    """``imagemap synthesize MESH -o out.glb|out.obj|out.png``: one mesh, one or more views."""
    import time

    from imagemap.cli.options import config_options, parse_colour, views_of
    from imagemap.database import Database
    from imagemap.depth.config import resolve_config
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
    config = resolve_config(args.preset, **config_options(args))  # a bad combination stops here
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
        preset=config,
        seed=args.seed,
        examples=examples,
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
