"""Orthographic ray casting with trimesh: planar depth, hit points and hit faces per pixel.

The one renderer of the project: ``data_gen`` renders its classes with it and
:mod:`imagemap.scene` renders meshes given by users (any view is a rotation of the
mesh followed by this cast along -z).

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

__all__ = ["OrthographicView", "RayHits", "cast_orthographic", "first_hits", "ray_backend"]

log = logging.getLogger(__name__)


def ray_backend() -> str:
    """The ray tracer trimesh will use: ``"embreex"`` if importable, else ``"rtree"``."""
    try:
        import embreex  # deferred: optional dependency (fast ray tracer)  # noqa: F401
    except ImportError:
        return "rtree"
    return "embreex"


def first_hits(
    mesh: trimesh.Trimesh, origins: np.ndarray, directions: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """First hit of every ray: (locations (N, 3), ray index (N,), face index (N,)).

    The same answer as ``mesh.ray.intersects_location(..., multiple_hits=False)``,
    which is what runs with embreex. Without embreex, trimesh's broad phase asks the
    rtree once per ray (about 50 us a ray: 1.5-2 s for a 200x150 picture, and a bulk
    ``intersection_v`` query is no faster). :func:`cast_orthographic` therefore passes
    ``grid`` candidates instead; this function is the general path.
    """
    return mesh.ray.intersects_location(origins, directions, multiple_hits=False)


def _grid_candidates(
    mesh: trimesh.Trimesh, view: OrthographicView, pixel_ids: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(face, ray) pairs whose face's xy bounding box contains the ray's pixel centre.

    The broad phase for rays parallel to z: each triangle's xy box covers a small
    block of pixel centres; all blocks are enumerated at once (no loop over rays).
    ``pixel_ids`` maps flat pixel index -> ray index (-1 where no ray is cast).
    """
    width, height = view.size
    xy = mesh.triangles[:, :, :2]
    low, high = xy.min(axis=1), xy.max(axis=1)
    x0 = view.center[0] - width / 2 * view.pixel_size  # left edge of column 0
    y0 = view.center[1] + height / 2 * view.pixel_size  # top edge of row 0
    # Column j's centre is x0 + (j + 0.5) p: columns with centres inside [low, high].
    col_lo = np.ceil((low[:, 0] - x0) / view.pixel_size - 0.5).astype(np.int64)
    col_hi = np.floor((high[:, 0] - x0) / view.pixel_size - 0.5).astype(np.int64)
    row_lo = np.ceil((y0 - high[:, 1]) / view.pixel_size - 0.5).astype(np.int64)
    row_hi = np.floor((y0 - low[:, 1]) / view.pixel_size - 0.5).astype(np.int64)
    # Widen by one pixel so centres on a box edge are not lost to rounding; the
    # narrow phase rejects the extra candidates.
    col_lo, row_lo = np.maximum(col_lo - 1, 0), np.maximum(row_lo - 1, 0)
    col_hi, row_hi = np.minimum(col_hi + 1, width - 1), np.minimum(row_hi + 1, height - 1)
    n_cols = np.maximum(col_hi - col_lo + 1, 0)
    n_rows = np.maximum(row_hi - row_lo + 1, 0)
    counts = n_cols * n_rows
    faces = np.repeat(np.arange(len(counts)), counts)
    start = np.cumsum(counts) - counts
    within = np.arange(counts.sum()) - np.repeat(start, counts)
    rows = row_lo[faces] + within // n_cols[faces]
    cols = col_lo[faces] + within % n_cols[faces]
    rays = pixel_ids[rows * width + cols]
    keep = rays >= 0
    return faces[keep], rays[keep]


def _narrow_phase(
    mesh: trimesh.Trimesh,
    origins: np.ndarray,
    directions: np.ndarray,
    candidate_faces: np.ndarray,
    candidate_rays: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """trimesh's plane and barycentric tests on candidate pairs; nearest hit per ray."""
    from trimesh import intersections  # deferred: start-up (trimesh)
    from trimesh import triangles as triangles_mod  # deferred: start-up (trimesh)

    triangles = mesh.triangles[candidate_faces]
    normals, valid_normal = triangles_mod.normals(triangles)
    # normals() drops degenerate triangles: keep the candidates that have one.
    triangles = triangles[valid_normal]
    candidate_faces = candidate_faces[valid_normal]
    candidate_rays = candidate_rays[valid_normal]
    location, valid = intersections.planes_lines(
        plane_origins=triangles[:, 0],
        plane_normals=normals,
        line_origins=origins[candidate_rays],
        line_directions=directions[candidate_rays],
    )
    barycentric = triangles_mod.points_to_barycentric(triangles[valid], location)
    inside = np.all((barycentric > -_tol_zero()) & (barycentric < 1 + _tol_zero()), axis=1)
    faces = candidate_faces[valid][inside]
    rays = candidate_rays[valid][inside]
    location = location[inside]
    distance = np.einsum("ij,ij->i", location - origins[rays], directions[rays])
    forward = distance > -1e-6
    faces, rays = faces[forward], rays[forward]
    location, distance = location[forward], distance[forward]
    # Nearest hit per ray: sort by (ray, distance), keep the first of each ray.
    order = np.lexsort((distance, rays))
    first = order[np.r_[True, np.diff(rays[order]) != 0]] if len(order) else order
    return location[first], rays[first], faces[first]


def _tol_zero() -> float:
    """trimesh's zero tolerance for the barycentric inside test."""
    from trimesh.constants import tol  # deferred: start-up (trimesh)

    return float(tol.zero)


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


#: A mesh less than this many world units across is cast on a copy scaled to unit size
#: (the hits scaled back): trimesh's test for degenerate triangles is absolute, and a
#: sphere 1e-6 units across (a model in kilometres read as metres) lost every triangle,
#: "nothing visible"; 1e-5 still rendered. Larger meshes are cast as they are, so their
#: renders do not change.
SMALLEST_CAST_EXTENT = 1e-3


def cast_orthographic(mesh: trimesh.Trimesh, view: OrthographicView) -> RayHits:
    """Cast one ray per pixel centre along -z and keep the first hit.

    Only the pixels inside the mesh's projected bounding box get a ray (the others
    cannot hit), which saves much of the time on small objects. A mesh smaller than
    :data:`SMALLEST_CAST_EXTENT` is cast at unit size and the hits scaled back.

    Example
    -------
    >>> sphere = trimesh.creation.icosphere(subdivisions=3)
    >>> hits = cast_orthographic(sphere, OrthographicView((0.0, 0.0), 0.05, (40, 40)))
    >>> bool(abs(np.nanmax(hits.z) - 1.0) < 0.01)
    True
    """
    extent = float(np.ptp(mesh.vertices, axis=0).max()) if len(mesh.vertices) else 0.0
    if 0.0 < extent < SMALLEST_CAST_EXTENT:
        origin = np.asarray(mesh.bounds[0], dtype=np.float64)
        unit = trimesh.Trimesh((mesh.vertices - origin) / extent, mesh.faces, process=False)
        center = ((view.center[0] - origin[0]) / extent, (view.center[1] - origin[1]) / extent)
        hits = cast_orthographic(
            unit, OrthographicView(center, view.pixel_size / extent, view.size)
        )
        return RayHits(
            hits.hit,
            hits.z * extent + origin[2],
            hits.points * extent + origin,
            hits.faces,
            hits.pixels,
        )
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
    directions = np.tile(np.array([0.0, 0.0, -1.0]), (len(origins), 1))
    if ray_backend() == "embreex":
        locations, ray_index, face_index = first_hits(mesh, origins, directions)
    else:
        pixel_ids = np.full(width * height, -1, dtype=np.int64)
        pixel_ids[pixels] = np.arange(pixels.size)
        faces, rays = _grid_candidates(mesh, view, pixel_ids)
        locations, ray_index, face_index = _narrow_phase(mesh, origins, directions, faces, rays)
    # Sort by pixel so the output does not depend on the backend's hit order.
    order = np.argsort(ray_index, kind="stable")
    locations, ray_index, face_index = locations[order], ray_index[order], face_index[order]
    hit_pixels = pixels[ray_index]
    z.flat[hit_pixels] = locations[:, 2]
    hit = np.zeros((height, width), dtype=bool)
    hit.flat[hit_pixels] = True
    return RayHits(hit, z, locations, face_index.astype(np.int64), hit_pixels)
