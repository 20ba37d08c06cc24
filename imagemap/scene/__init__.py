"""Meshes, views and mesh files: what the database and the mesh front end stand on.

- :mod:`~imagemap.scene.views`: views, depth rendering (:mod:`~imagemap.scene.raycast`)
  and the mesh's colours per pixel;
- :mod:`~imagemap.scene.files`: reading meshes, writing textured GLB and OBJ;
- :mod:`~imagemap.scene.bake`: projection UVs for one view, a baked UV atlas for several;
- :mod:`~imagemap.scene.coverage`: views chosen by how much of the surface they see;
- :mod:`~imagemap.scene.surface`: what the artist set on a mesh, kept on the result;
- :mod:`~imagemap.scene.examples`: textured meshes as database examples.

Nothing here synthesizes: the package imports neither the engine, the front ends nor
the database (the layout test checks it), so that :mod:`imagemap.database` can read
mesh examples and the mesh front end (:mod:`imagemap.mesh`) can stand on both.
"""

from __future__ import annotations

from imagemap.scene.bake import bake_views, project_texture, rasterize_uv, uv_atlas
from imagemap.scene.examples import MeshExample, mesh_examples
from imagemap.scene.files import (
    MESH_SUFFIXES,
    TEXTURED_SUFFIXES,
    check_textured,
    export_textured,
    file_digest,
    is_mesh_path,
    load_mesh,
    textured_mesh,
)
from imagemap.scene.views import (
    DEFAULT_SIZE,
    FRONT,
    NAMED_VIEWS,
    MeshRender,
    View,
    parse_view,
    parse_views,
    render_colours,
    render_mesh,
    render_textured,
    sample_image,
    surface_colours,
)

__all__ = [
    "DEFAULT_SIZE",
    "FRONT",
    "MESH_SUFFIXES",
    "NAMED_VIEWS",
    "TEXTURED_SUFFIXES",
    "MeshExample",
    "MeshRender",
    "View",
    "bake_views",
    "check_textured",
    "export_textured",
    "file_digest",
    "is_mesh_path",
    "load_mesh",
    "mesh_examples",
    "parse_view",
    "parse_views",
    "project_texture",
    "rasterize_uv",
    "render_colours",
    "render_mesh",
    "render_textured",
    "sample_image",
    "surface_colours",
    "textured_mesh",
    "uv_atlas",
]
