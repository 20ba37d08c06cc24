"""Orthographic ray casting with trimesh: planar depth, hit points and hit faces per pixel.

One ray per pixel centre, all parallel to -z, starting on a plane in front of the
object. Pixel (row, col) is ray ``row * W + col``; row 0 is the top of the picture
(largest y), col 0 the left (smallest x). Because the rays are parallel and start on
a plane of constant z, the hit's z *is* the planar depth (trimesh's ``camera_rays``
are perspective and give distance along unit rays instead).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
import trimesh

__all__ = ["OrthographicView", "RayHits", "cast_orthographic", "ray_backend"]

log = logging.getLogger(__name__)


def ray_backend() -> str:
    """The ray tracer trimesh will use: ``"embreex"`` if importable, else ``"rtree"``."""
    try:
        import embreex  # noqa: F401
    except ImportError:
        return "rtree"
    return "embreex"


def _intersector(mesh: trimesh.Trimesh):
    if ray_backend() == "embreex":
        from trimesh.ray.ray_pyembree import RayMeshIntersector

        return RayMeshIntersector(mesh)
    from trimesh.ray.ray_triangle import RayMeshIntersector

    return RayMeshIntersector(mesh)


@dataclass(frozen=True)
class OrthographicView:
    """A window of the plane z = const seen along -z.

    Parameters
    ----------
    center : (float, float)
        World (x, y) at the centre of the picture.
    pixel_size : float
        World units per pixel (square pixels).
    size : (int, int)
        Picture (width, height) in pixels.
    """

    center: tuple[float, float]
    pixel_size: float
    size: tuple[int, int]

    def pixel_centers(self) -> tuple[np.ndarray, np.ndarray]:
        """World x (W,) of the columns and y (H,) of the rows (row 0 at the top)."""
        width, height = self.size
        xs = self.center[0] + (np.arange(width) + 0.5 - width / 2) * self.pixel_size
        ys = self.center[1] - (np.arange(height) + 0.5 - height / 2) * self.pixel_size
        return xs, ys


@dataclass
class RayHits:
    """Per-pixel results of a cast; ``hit`` marks foreground pixels.

    ``z`` (H, W) is the world z of the first hit (NaN where missed); ``points`` (N, 3),
    ``faces`` (N,) and ``pixels`` (N,) flat pixel indices list the N hits.
    """

    hit: np.ndarray
    z: np.ndarray
    points: np.ndarray
    faces: np.ndarray
    pixels: np.ndarray


def cast_orthographic(mesh: trimesh.Trimesh, view: OrthographicView) -> RayHits:
    """Cast one ray per pixel centre along -z and keep the first hit.

    Only the pixels inside the mesh's projected bounding box get a ray (the others
    cannot hit), which saves much of the time on small objects.

    Example
    -------
    >>> sphere = trimesh.creation.icosphere(subdivisions=3)
    >>> hits = cast_orthographic(sphere, OrthographicView((0.0, 0.0), 0.05, (40, 40)))
    >>> bool(abs(np.nanmax(hits.z) - 1.0) < 0.01)
    True
    """
    width, height = view.size
    xs, ys = view.pixel_centers()
    low, high = mesh.bounds
    cols = np.flatnonzero((xs >= low[0]) & (xs <= high[0]))
    rows = np.flatnonzero((ys >= low[1]) & (ys <= high[1]))
    z = np.full((height, width), np.nan, dtype=np.float64)
    empty = np.zeros(0, dtype=np.int64)
    if cols.size == 0 or rows.size == 0:
        return RayHits(np.zeros((height, width), bool), z, np.zeros((0, 3)), empty, empty)
    grid_rows, grid_cols = np.meshgrid(rows, cols, indexing="ij")
    pixels = (grid_rows * width + grid_cols).ravel()
    origins = np.stack(
        [xs[grid_cols.ravel()], ys[grid_rows.ravel()], np.full(pixels.size, high[2] + 1.0)],
        axis=1,
    )
    directions = np.broadcast_to(np.array([0.0, 0.0, -1.0]), origins.shape)
    locations, ray_index, face_index = _intersector(mesh).intersects_location(
        origins, directions, multiple_hits=False
    )
    # Sort by pixel so the output does not depend on the backend's hit order.
    order = np.argsort(ray_index, kind="stable")
    locations, ray_index, face_index = locations[order], ray_index[order], face_index[order]
    hit_pixels = pixels[ray_index]
    z.flat[hit_pixels] = locations[:, 2]
    hit = np.zeros((height, width), dtype=bool)
    hit.flat[hit_pixels] = True
    return RayHits(hit, z, locations, face_index.astype(np.int64), hit_pixels)
