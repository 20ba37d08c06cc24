"""The mesh front end: textured meshes from examples.

- :mod:`~imagemap.mesh.colorize`: :func:`colorize_mesh`, a synthesis per view (the depth
  front end) baked into the mesh's UV atlas, or the synthesis in a shared UV atlas;
- :mod:`~imagemap.mesh.uvspace`: that synthesis in the atlas itself, with surface guides;
- :mod:`~imagemap.mesh.maps`: the examples' PBR maps carried onto the mesh.

Meshes, views, ray casting and mesh files are :mod:`imagemap.scene`, below the database.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from imagemap.mesh.colorize import MeshResult, colorize_mesh

__all__ = ["MeshResult", "colorize_mesh"]


def __getattr__(name: str) -> Any:
    # Deferred (PEP 562): importing a submodule such as ``imagemap.mesh.library`` (every
    # batch worker does) must not import the colorization and its registration, which pull
    # in trimesh and networkx (about 0.45 s of a worker's start).
    if name in __all__:
        from imagemap.mesh import colorize  # deferred: start-up (trimesh, networkx; above)

        return getattr(colorize, name)
    raise AttributeError(f"module 'imagemap.mesh' has no attribute {name!r}")
