"""Meshes in, textured meshes out.

- :mod:`~imagemap.mesh.views`: views, depth rendering (:mod:`~imagemap.mesh.raycast`)
  and the mesh's colours per pixel;
- :mod:`~imagemap.mesh.files`: reading meshes, writing textured GLB and OBJ;
- :mod:`~imagemap.mesh.bake`: projection UVs for one view, a baked UV atlas for several;
- :mod:`~imagemap.mesh.examples`: textured meshes as database examples;
- :mod:`~imagemap.mesh.colorize`: a synthesis per view, textured onto the mesh.

The submodules below ``colorize`` do not import the depth front end or the
database, so that :mod:`imagemap.database` can find mesh examples without an
import circle; ``colorize_mesh`` and ``MeshResult`` are imported on first use.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

from imagemap.mesh.bake import bake_views, project_texture, rasterize_uv, uv_atlas
from imagemap.mesh.examples import RENDER_VERSION, MeshExample, mesh_examples
from imagemap.mesh.files import (
    MESH_SUFFIXES,
    TEXTURED_SUFFIXES,
    check_textured,
    export_textured,
    file_digest,
    is_mesh_path,
    load_mesh,
    textured_mesh,
)
from imagemap.mesh.views import (
    DEFAULT_SIZE,
    FRONT,
    NAMED_VIEWS,
    MeshRender,
    View,
    fill_from_nearest,
    parse_view,
    parse_views,
    render_colours,
    render_mesh,
    render_textured,
    sample_image,
    surface_colours,
)

if TYPE_CHECKING:
    from imagemap.mesh.colorize import MeshResult, colorize_mesh

__all__ = [
    "DEFAULT_SIZE",
    "FRONT",
    "MESH_SUFFIXES",
    "NAMED_VIEWS",
    "RENDER_VERSION",
    "TEXTURED_SUFFIXES",
    "MeshExample",
    "MeshRender",
    "MeshResult",
    "View",
    "bake_views",
    "check_textured",
    "colorize_mesh",
    "export_textured",
    "file_digest",
    "fill_from_nearest",
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


def __getattr__(name: str):
    """``colorize_mesh`` and ``MeshResult`` on first use (they need the depth front end)."""
    if name in ("colorize_mesh", "MeshResult"):
        value = getattr(importlib.import_module("imagemap.mesh.colorize"), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
