"""The mesh route from a loaded mesh to its written files: one function for
``imagemap synthesize MESH`` and for every mesh of ``imagemap batch``.

:func:`texture_mesh` chooses the path (uv-space when the examples share the query's UV
layout, registered when mesh examples are in other layouts, else views; ``auto`` views by
coverage), synthesizes, carries the examples' PBR maps (on every path) and what the
artist set on the input (normals, alpha, material);
:func:`mesh_writers` stages the files (the mesh in its format, and beside it what glTF
has no slot for). Both commands call these two with the same :class:`MeshRequest`, so
the same options give the same bytes through either (``tests/test_batch.py``).
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from imagemap.io import InputError, image_writer
from imagemap.materials import SIDE_MAPS, transfer_maps
from imagemap.mesh.colorize import (
    MeshResult,
    colorize_mesh,
    registrable_examples,
    uv_layout_examples,
)
from imagemap.mesh.fineviews import fine_render, fine_view_maps
from imagemap.mesh.library import ExampleSet
from imagemap.mesh.maps import atlas_maps, bake_maps, with_surface_maps
from imagemap.outputs import exported
from imagemap.progress import progress, step_line
from imagemap.scene.bake import bake_views, project_texture
from imagemap.scene.coverage import choose_views
from imagemap.scene.examples import MeshExample
from imagemap.scene.files import export_textured
from imagemap.scene.surface import frame_mesh, keep_surface
from imagemap.scene.views import DEFAULT_SIZE, FRONT, View

__all__ = [
    "MeshRequest",
    "TexturedResult",
    "mesh_writers",
    "side_map_path",
    "texture_mesh",
]


@dataclass(frozen=True)
class MeshRequest:
    """How a mesh is textured: what both commands pass to :func:`texture_mesh`.

    Attributes
    ----------
    views : tuple of View
        The views (with ``auto_views``: the candidates, narrowed by coverage per mesh).
    auto_views : bool
        ``--views auto``: choose among ``views`` by coverage
        (:func:`imagemap.scene.coverage.choose_views`).
    size : (int, int)
        Each view's depth map (width, height).
    texture_size : int or None
        The texture's side; None: the mesh's own atlas resolution.
    config : DepthConfig or str
        The resolved configuration (or a preset name).
    seed : int
    examples : tuple of str or None
        The examples asked for (None: chosen).
    uv_space : bool or None
        ``--uv-space`` (True), ``--no-uv-space`` (False), detected (None).
    registered : bool or None
        Mesh examples in other UV layouts registered to the query and resampled into its
        atlas (None: when there are such examples; ``--no-register``: False, the views).
    maps : bool
        Carry the examples' PBR maps (``--no-maps``: False).
    """

    views: tuple[View, ...] = (FRONT,)
    auto_views: bool = False
    size: tuple[int, int] = DEFAULT_SIZE
    texture_size: int | None = None
    config: Any = "busts"
    seed: int = 0
    examples: tuple[str, ...] | None = None
    uv_space: bool | None = None
    registered: bool | None = None
    maps: bool = True


@dataclass
class TexturedResult:
    """A textured mesh ready to write, and what made it.

    Attributes
    ----------
    made : MeshResult
        The synthesis (path, renders, per-view results).
    textured : trimesh.Trimesh
        The mesh to write: texture, PBR maps, normals, alpha and material settings.
    views : tuple of View
        The views synthesized (empty on the uv-space path).
    side_maps : dict
        Maps glTF has no slot for, written beside the mesh as ``STEM_KIND.png``
        (``"height"``: 16-bit grey).
    """

    made: MeshResult
    textured: Any
    views: tuple[View, ...]
    side_maps: dict[str, Any] = field(default_factory=dict)


def _say(quiet: bool) -> Callable[[str], None]:
    def say(text: str) -> None:
        if not quiet:
            print(f"imagemap: {text}", file=sys.stderr)

    return say


def _render_mesh_examples(examples: ExampleSet, views, size, quiet: bool) -> None:
    """Render (or read from the cache) every mesh example at every view, each named
    (a prepared set has them rendered already)."""
    if examples.source is None:
        return
    for view in views:
        found = [e for e in examples.at_view(view, size) if isinstance(e, MeshExample)]
        todo = [e for e in found if not e.cache_path().is_file()]
        if not todo:
            continue
        _say(quiet)(
            f"rendering {len(todo)} mesh example(s) from view {view} "
            "(first use; cached for the next runs)"
        )
        for example in progress(todo, desc=f"mesh examples at {view}", quiet=quiet):
            if not quiet and not sys.stderr.isatty():
                print(f"imagemap:   {example.name} ({example.mesh_path.name})", file=sys.stderr)
            _ = example.depth  # renders and caches


def _with_atlas_maps(made: MeshResult, mesh):
    """``made.mesh`` with the examples' PBR maps carried beside its colour (uv-space and
    registered paths: each texel's from where its colour came, :func:`atlas_maps`)."""
    if not made.examples:
        return made.mesh
    # The normal map in the frames of the mesh as written, as on the views path.
    maps = atlas_maps(made.results[0], made.examples, frame_mesh(made.mesh, mesh))
    return with_surface_maps(made.mesh, maps)


def _with_view_maps(made: MeshResult, mesh, examples: ExampleSet, size):
    """``made.mesh`` with the examples' PBR maps baked beside its colour (views path),
    and the maps glTF has no slot for (:data:`~imagemap.mesh.maps.SIDE_MAPS`), by kind."""
    if not made.renders:
        return made.mesh, {}
    renders = made.renders
    width = made.mesh.visual.material.baseColorTexture.size[0]  # type: ignore[attr-defined]

    # The bakes give the texture itself, not rounded to 8 bits: the 16-bit height map
    # keeps the examples' precision (the same atlas as the colour's bake).
    def bake(images, picture_normals=False):
        if len(made.renders) == 1:
            return project_texture(mesh, made.renders[0], images[0], texture_only=True)
        return bake_views(mesh, made.renders, images, width, texture_only=True,
                          picture_normals=picture_normals)  # fmt: skip

    databases = [examples.at_view(r.view, size) for r in renders]
    # The normal map in the frames of the mesh as written (keep_surface's normals), the
    # frames of the TANGENTs export_textured writes beside them.
    frames = frame_mesh(made.mesh, mesh)
    if made.fine:
        # Copied at the texels' resolution through the colour's own fine copy (#46
        # item 2); the normals turned into world directions at each texel's surface.
        view_maps = fine_view_maps(examples, renders, made.results, databases, made.fine)
    else:
        view_maps = [transfer_maps(r, db) for r, db in zip(made.results, databases, strict=True)]
    if not any(view_maps):
        return made.mesh, {}
    projection = len(renders) == 1
    if made.fine and projection and any("normal" in m for m in view_maps):
        # One view copied finer: its normals are turned at the surface points the view
        # sees at the fine size (the texels of the projection are the fine pixels).
        renders = [fine_render(mesh, renders[0], made.fine[0].factor)]
    maps = bake_maps(
        mesh,
        renders,
        view_maps,
        bake,
        frames,
        projection=projection,
        bake_normals=(
            (lambda images: bake(images, picture_normals=True))
            if made.fine and not projection
            else None
        ),
    )
    side = {kind: maps.pop(kind) for kind in SIDE_MAPS if kind in maps}
    return with_surface_maps(made.mesh, maps), side


def texture_mesh(
    mesh, examples: ExampleSet, request: MeshRequest, *, quiet: bool = True
) -> TexturedResult:
    """Texture a loaded mesh as ``imagemap synthesize MESH`` does (and every batch job).

    Parameters
    ----------
    mesh : trimesh.Trimesh
        The query, loaded and checked (:func:`imagemap.scene.files.load_mesh`).
    examples : ExampleSet
        The database (on disk, or a batch's prepared set).
    request : MeshRequest
    quiet : bool
        No messages on stderr (which path, which views, examples rendered).

    Returns
    -------
    TexturedResult
    """
    if not isinstance(request, MeshRequest):
        raise InputError(f"request: expected a MeshRequest, got {request!r}")
    say = _say(quiet)
    names = list(request.examples) if request.examples else None
    views = tuple(request.views)
    # Examples in the query's UV layout: synthesized in the atlas, no view is rendered.
    in_layout = uv_layout_examples(mesh, examples, request.uv_space, names)
    # Else mesh examples in other layouts: registered to the query, no view either.
    to_register = (
        registrable_examples(examples, names)
        if in_layout is None and request.uv_space is not False and request.registered is not False
        else None
    )
    if in_layout is not None:
        views = ()
        used = ", ".join(e.name for e in in_layout)
        say(f"uv-space path: examples in the mesh's UV layout: {used}")
    elif to_register is not None:
        views = ()
        say(f"registered path: {len(to_register)} mesh examples registered to the mesh")
    elif request.auto_views:
        views = tuple(choose_views(mesh, views))
        say(f"views chosen by coverage: {'; '.join(str(v) for v in views)}")
    if views:
        _render_mesh_examples(examples, views, request.size, quiet)
    # Step lines whatever stderr is (a program running the command reads them): the
    # views (or the atlas), the bake, the PBR maps.
    total = (len(views) + 1 if views else 1 + (to_register is not None)) + (
        1 if request.maps and views else 0
    )
    done = 0

    def step(text: str) -> None:
        nonlocal done
        done += 1
        say(step_line(done, total, text))

    made = colorize_mesh(
        mesh,
        examples,
        list(views),
        size=request.size,
        preset=request.config,
        seed=request.seed,
        examples=names,
        quiet=quiet or not sys.stderr.isatty(),
        uv_space=in_layout if in_layout is not None else False,
        registered=to_register is not None,
        step=step,
        texture_size=request.texture_size or None,
    )
    coloured, side = made.mesh, {}
    if request.maps:
        if views:
            step("baking the examples' PBR maps")
        if made.path == "views":
            coloured, side = _with_view_maps(made, mesh, examples, request.size)
        else:
            coloured = _with_atlas_maps(made, mesh)
    textured = keep_surface(coloured, mesh)
    return TexturedResult(made=made, textured=textured, views=views, side_maps=side)


def side_map_path(output: str | Path, kind: str) -> Path:
    """Where a map glTF has no slot for is written beside a mesh: ``STEM_KIND.png``.

    Examples
    --------
    >>> side_map_path("out/fish.glb", "height").as_posix()
    'out/fish_height.png'
    """
    output = Path(output)
    return output.with_name(f"{output.stem}_{kind}.png")


def mesh_writers(
    result: TexturedResult, output: str | Path, companions, scale: float = 1.0
) -> tuple[dict, Callable[[], None]]:
    """:func:`imagemap.outputs.write_all` writers of a textured mesh's files, and a clean-up.

    The mesh is exported into a staging folder (:func:`imagemap.outputs.exported`) as
    ``output``'s format, scaled by ``scale`` (metres per source unit); beside it, each
    map glTF has no slot for (``STEM_height.png``: 16-bit grey). Every file must be
    ``output`` or one of ``companions`` (checked in the output plan before any work);
    a side map that is not is a ``RuntimeError`` (a plan that missed it).
    """
    output = Path(output)
    planned = {Path(p) for p in companions}
    side = {side_map_path(output, kind): array for kind, array in result.side_maps.items()}
    unplanned = sorted(str(p) for p in side if p not in planned)
    if unplanned:
        raise RuntimeError(f"{output}: {', '.join(unplanned)} not checked by the output plan")
    textured = result.textured
    writers, cleanup = exported(
        lambda path: export_textured(textured, path, scale=scale),
        output,
        [p for p in planned if p not in side],
    )
    for path, array in side.items():
        # Heights want more than a texture's 8 bits (glTF has no slot for them anyway).
        writers[path] = image_writer(array[..., 0] if array.ndim == 3 else array, bits=16)
    return writers, cleanup
