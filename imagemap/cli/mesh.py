"""The mesh route of ``imagemap synthesize``: a mesh in, a textured mesh (or its map) out."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from imagemap.errors import InputError

__all__ = ["is_mesh_request", "run_mesh_synthesize"]

DEFERRED_IMPORTS = "start-up: building the parser loads no scientific module"


def is_mesh_request(args: argparse.Namespace) -> bool:
    """Whether ``imagemap synthesize`` was given a mesh or asked for a textured mesh."""
    # The suffixes, not imagemap.scene (30-45 ms of CPU): a depth map's synthesis does
    # not import it (imagemap.scene.is_mesh_path is this suffix test).
    from imagemap.outputs import MESH_SUFFIXES, TEXTURED_SUFFIXES

    return any(Path(p).suffix.lower() in MESH_SUFFIXES for p in args.depth) or (
        Path(args.output).suffix.lower() in TEXTURED_SUFFIXES
    )


#: Views of the --preview sheet: the front and a three-quarter view from above.
PREVIEW_VIEWS = ("0,0", "35,20")
#: A stated size outside this range (metres) gets a hint about --units: smaller than
#: a coin or taller than a ten-storey building is rarely what an artist meant.
PLAUSIBLE_METRES = (0.01, 30.0)


def _mesh_preview(textured, database, first_name: str, size):
    """The textured result from :data:`PREVIEW_VIEWS` beside the first example's picture
    (a mesh example rendered the same way; a picture example as it is)."""
    import numpy as np

    from imagemap.scene import MeshExample, load_mesh, render_textured
    from imagemap.scene.views import parse_view

    example = database[first_name]
    tiles = [render_textured(textured, parse_view(v), size, shaded=True) for v in PREVIEW_VIEWS]
    if isinstance(example, MeshExample):
        reference = load_mesh(example.mesh_path)
        tiles += [
            render_textured(reference, parse_view(v), size, shaded=True) for v in PREVIEW_VIEWS
        ]
    else:
        from skimage.transform import (
            resize,
        )  # deferred: start-up: skimage.transform (0.4 s) only for a resized texture

        picture = np.where(example.mask[..., None], example.image, 1.0)
        tiles.append(resize(picture, (size[1], size[0]), order=1, anti_aliasing=True))
    gap = np.ones((size[1], 4, 3), dtype=np.float32)
    row = [tiles[0]]
    for tile in tiles[1:]:
        row += [gap, np.asarray(tile, dtype=np.float32)]
    return np.concatenate(row, axis=1)


def how_made(made, views) -> str:
    """The closing line's "3 view(s)", or "its UV atlas" on the uv-space and registered paths."""
    if made.path == "registered":
        return "its UV atlas (mesh examples registered)"
    return "its UV atlas" if made.path == "uv-space" else f"{len(views)} view(s)"


def _guard_memory(args: argparse.Namespace, mesh, views) -> None:
    """The memory guard of the mesh route (imagemap.depth.budget.guard_mesh): the views'
    size and the texture's (the one the bake would choose when not given)."""
    import numpy as np

    from imagemap.depth.budget import guard_mesh
    from imagemap.scene.bake import texture_size_for
    from imagemap.scene.views import DEFAULT_MARGIN

    size = args.size
    texture = args.texture_size
    if texture is None:
        extent = float(np.ptp(np.asarray(mesh.vertices), axis=0).max())
        pixel = extent / (min(size) * (1 - 2 * DEFAULT_MARGIN))
        try:
            texture = texture_size_for(mesh, pixel)
        except InputError:  # no usable UVs: the bake says so itself
            texture = 512
    check = False if args.no_memory_check else None  # None: IMAGEMAP_NO_MEMORY_CHECK decides
    guard_mesh(size, max(len(views), 1), texture, str(args.depth[0]), check)


def mesh_folder_hint(db) -> str | None:
    """A hint when ``db`` holds no mesh examples but ``db/meshes/`` does.

    ``python -m data_gen ... --meshes`` writes the depth examples in ``OUT/`` and the
    textured meshes in ``OUT/meshes/``, which ``--db OUT`` does not read: a mesh query then
    takes the views path from the depth examples, where ``--db OUT/meshes`` would register
    the meshes onto it (one palette on every side, docs/meshes.md).
    """
    from imagemap.outputs import TEXTURED_SUFFIXES

    folder = Path(db)
    sub = folder / "meshes"
    if not sub.is_dir() or any(p.suffix.lower() in TEXTURED_SUFFIXES for p in folder.iterdir()):
        return None
    found = [p for p in sub.iterdir() if p.suffix.lower() in TEXTURED_SUFFIXES]
    if not found:
        return None
    return (
        f"{folder}: no mesh examples here, but {len(found)} in {sub}: this mesh is made "
        f"through views from the depth examples; --db {sub} registers the meshes onto it "
        "in 3-D instead (docs/meshes.md)"
    )


def run_mesh_synthesize(args: argparse.Namespace) -> int:
    """``imagemap synthesize MESH -o out.glb|out.obj|out.png``: one mesh, one or more views."""
    import time

    import numpy as np

    from imagemap.cli.options import config_options, parse_colour, views_of
    from imagemap.database import Database
    from imagemap.depth.config import resolve_config
    from imagemap.io import image_writer
    from imagemap.materials import SIDE_MAPS, database_map_kinds
    from imagemap.mesh.library import ExampleSet
    from imagemap.mesh.route import MeshRequest, mesh_writers, texture_mesh
    from imagemap.outputs import OutputPlan, write_all, written_companions
    from imagemap.scene import TEXTURED_SUFFIXES, is_mesh_path, load_mesh
    from imagemap.scene.files import unit_scale

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
    background = parse_colour(args.background)
    config = resolve_config(args.preset, **config_options(args))  # a bad combination stops here
    scale = unit_scale(getattr(args, "units", None), getattr(args, "scale", None))
    views = views_of(args)
    quiet = bool(args.quiet)
    mesh = load_mesh(source)  # bad input stops here, before any work
    if args.size is None:
        # Views at least as fine as the texels they fill (issue #46: stair steps).
        from imagemap.scene.bake import view_size_for

        args.size = view_size_for(mesh, views, args.texture_size)
        if not quiet:
            print(f"imagemap: views at {args.size[0]}x{args.size[1]}", file=sys.stderr)
    database = Database.from_directory(args.db, view=views[0], size=args.size)
    hint = mesh_folder_hint(args.db)
    if hint is not None and not quiet:
        print(f"imagemap: {hint}", file=sys.stderr)
    if args.exclude:
        database = database.without(*[n.strip() for n in args.exclude.split(",")])
    examples = [n.strip() for n in args.examples.split(",")] if args.examples else None
    for name in examples or []:
        database[name]  # unknown names fail here
    plan = OutputPlan(overwrite=args.overwrite)
    # With the MTL and textures it reads, and its truth (kept unless --overwrite).
    plan.add_query(source, "input mesh", overwrite=args.overwrite, hint="; --overwrite replaces it")
    plan.add_database(database, args.db)
    # An OBJ's .mtl and texture are checked with it (imagemap.outputs.written_companions),
    # and the height map glTF has no slot for (STEM_height.png) when an example has one.
    companions = written_companions(output)
    if output.suffix.lower() != ".png":
        kinds = [] if getattr(args, "no_maps", False) else database_map_kinds(database, examples)
        companions = written_companions(output, [k for k in SIDE_MAPS if k in kinds])
    plan.add_output(output, "-o", suffixes=(*TEXTURED_SUFFIXES, ".png"), companions=companions)
    for option, path, suffixes in (
        ("--provenance", args.provenance, (".png",)),
        ("--preview", args.preview, (".png",)),
        ("--report", args.report, (".json",)),
    ):
        if path:
            plan.add_output(path, option, suffixes=suffixes)
    plan.check()
    _guard_memory(args, mesh, views)  # before any work: --size and --texture-size
    request = MeshRequest(
        views=tuple(views),
        auto_views=getattr(args, "views", None) == "auto",
        size=tuple(args.size),
        texture_size=args.texture_size,
        config=config,
        seed=args.seed,
        examples=tuple(examples) if examples else None,
        uv_space=getattr(args, "uv_space", None),
        registered=getattr(args, "registered", None),
        maps=not getattr(args, "no_maps", False),
    )
    start = time.perf_counter()
    done = texture_mesh(mesh, ExampleSet.of(database), request, quiet=quiet)
    made, textured, views = done.made, done.textured, done.views
    seconds = time.perf_counter() - start
    first = made.results[0]
    writers = {}
    if output.suffix.lower() == ".png":
        picture = first.rgba if background is None else first.on_background(background)
        writers[output] = image_writer(picture)
    if args.provenance:
        writers[Path(args.provenance)] = image_writer(first.provenance)
    if args.preview:
        sheet = _mesh_preview(textured, database, first.example_names[0], args.size)
        writers[Path(args.preview)] = image_writer(sheet)
    if args.report:
        report = {
            "query": str(source),
            "output": str(output),
            "path": made.path,
            "views": [str(v) for v in views],
            "size": list(args.size),  # each view's (the default: imagemap.scene.bake.view_size_for)
            "examples": [r.example_names for r in made.results],
            "seconds": seconds,
            "preset": args.preset,
            "seed": args.seed,
            "scale_to_metres": scale,
        }
        import json

        text = json.dumps(report, indent=2)
        writers[Path(args.report)] = lambda tmp: Path(tmp).write_text(text)
    cleanup = None
    if output.suffix.lower() != ".png":  # the mesh's files join the set (staged, then moved)
        files, cleanup = mesh_writers(done, output, companions, scale)
        writers.update(files)
    try:
        write_all(writers)
    finally:
        if cleanup is not None:
            cleanup()
    if not quiet:
        extent = np.ptp(np.asarray(mesh.vertices), axis=0) * scale
        size_text = " x ".join(f"{v:.3g}" for v in extent)
        how = "source units kept, read as metres" if scale == 1.0 else f"scaled by {scale:g}"
        print(
            f"wrote {output} from {how_made(made, views)} of {source.name} in {seconds:.2f} s; "
            f"size {size_text} m ({how})",
            file=sys.stderr,
        )
        low, high = PLAUSIBLE_METRES
        if output.suffix.lower() != ".png" and not (low <= extent.max() <= high):
            print(
                f"imagemap: note: {extent.max():.3g} m across; if the mesh was modelled in "
                "other units, give --units (mm, cm, in, ft) or --scale",
                file=sys.stderr,
            )
    return 0
