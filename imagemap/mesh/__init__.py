"""The mesh front end: textured meshes from examples.

- :mod:`~imagemap.mesh.colorize`: :func:`colorize_mesh`, a synthesis per view (the depth
  front end) baked into the mesh's UV atlas, or the synthesis in a shared UV atlas;
- :mod:`~imagemap.mesh.uvspace`: that synthesis in the atlas itself, with surface guides;
- :mod:`~imagemap.mesh.maps`: the examples' PBR maps carried onto the mesh.

Meshes, views, ray casting and mesh files are :mod:`imagemap.scene`, below the database.
"""

from __future__ import annotations

from imagemap.mesh.colorize import MeshResult, colorize_mesh

__all__ = ["MeshResult", "colorize_mesh"]
