"""Colorizing a mesh: one synthesis per view, textured by projection or baked into an atlas."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from imagemap.database import Database, database_at_view
from imagemap.io import InputError
from imagemap.mesh.bake import bake_views, project_texture
from imagemap.mesh.files import load_mesh
from imagemap.mesh.views import (
    DEFAULT_SIZE,
    FRONT,
    MeshRender,
    View,
    parse_view,
    parse_views,
    render_mesh,
)

__all__ = ["MeshResult", "colorize_mesh"]


@dataclass
class MeshResult:
    """A textured mesh made from one or several views, and what made it."""

    mesh: object  # trimesh.Trimesh with UVs and texture
    renders: list[MeshRender]
    results: list  # one ColorizeResult per view

    @property
    def image(self) -> np.ndarray:
        """The first view's synthesized map (H, W, 3)."""
        return self.results[0].image


def colorize_mesh(
    mesh,
    database: Database | dict[str, Database],
    views: list[View] | str | None = None,
    *,
    size: tuple[int, int] = DEFAULT_SIZE,
    texture_size: int = 512,
    preset="busts",
    seed: int = 0,
    **colorize_options,
) -> MeshResult:
    """Synthesize image-maps for a mesh from one or several views and texture it.

    Each view is synthesized from the database's examples seen from the same view
    (mesh examples are rendered at that view; picture examples are used as they
    are). One view: projection UVs; several: baked into a UV atlas.

    Parameters
    ----------
    mesh : trimesh.Trimesh or path
    database : Database or dict
        The examples; or, prepared for each view (:func:`prepare_database`), a dict
        from ``str(view)`` (``"az,el"``) to Database.
    views : list of View or str, optional
        The front by default; e.g. ``"front,back,left,right"``.
    size : (int, int)
        (width, height) of each view's depth map.
    texture_size : int
        Atlas size when several views are baked.
    preset, seed, **colorize_options
        As :func:`imagemap.colorize`.
    """
    from imagemap.depth.pipeline import colorize

    if not hasattr(mesh, "faces"):
        mesh = load_mesh(mesh)
    if views is None:
        views = [FRONT]
    elif isinstance(views, str):
        views = parse_views(views)
    views = [parse_view(v) for v in views]
    renders, results = [], []
    for view in views:
        render = render_mesh(mesh, view, size)
        if not render.mask.any():
            raise InputError(f"nothing of the mesh is visible from view {view}")
        if isinstance(database, dict):
            examples = database[str(view)]
        else:
            examples = database_at_view(database, view, size)
        result = colorize(
            render.depth,
            examples,
            preset=preset,
            seed=seed,
            **colorize_options,
        )
        renders.append(render)
        results.append(result)
    if len(views) == 1:
        textured = project_texture(mesh, renders[0], results[0].image)
    else:
        textured = bake_views(mesh, renders, [r.image for r in results], texture_size)
    return MeshResult(mesh=textured, renders=renders, results=results)
