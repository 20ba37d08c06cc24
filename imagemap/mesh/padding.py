"""Padding by the surface itself: an atlas' gutter continued across the chart seams.

One module for one job: where on the surface each padding texel of a UV atlas lies.

A texel outside the charts (the padding, or gutter) has no surface point of its own. Filled
from the nearest used texel (:func:`imagemap.core.blend.fill_background`), a window at a
chart's border sees that border's values repeated, not the surface on the other side of
the seam. Here each padding texel within a reach of the charts gets the surface point that
*continues* its nearest chart across the border, as seamless texture atlases fill their
gutter from the 3-D neighbourhood (Ray et al., "Invisible seams", 2010; Liu et al.,
"Seamless: seam erasure and seam-aware decoupling of shape from mesh resolution", 2017):

1. the nearest used texel's face and its UV -> 3-D map (affine on the triangle) turn the
   padding texel's UV offset from that texel into a 3-D step in the face's plane;
2. the step is walked on the surface as a straightest path (:func:`walk`): across each
   edge it passes, into the face on the other side (of the *welded* mesh, so across the
   UV seams too), the step turned about the edge into that face's plane (unfolded);
3. where it ends is a face and barycentrics of the mesh, so a UV point in that face's own
   chart: the padding texel takes the atlas' values there (:meth:`SurfacePadding.apply`).

On a smooth surface this is the brief's "affine continuation snapped to the closest point"
to first order; on a sharp edge (a box) the closest point of a point continued in the
face's plane is the edge itself, every padding texel beyond it the edge's value again,
where the walk goes on down the other face. A walk that meets a boundary of the mesh (the
surface ends) stops there: the border's value, as before.

Examples
--------
A strip folded at a right angle, its two faces' UVs apart (a seam at the fold): the
padding texels beside the first chart's seam continue onto the second face.

>>> vertices = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [0, 1, 1], [1, 1, 1.0]])
>>> faces = np.array([[0, 1, 3], [0, 3, 2], [2, 3, 5], [2, 5, 4]])
>>> unwelded = np.r_[vertices, vertices[[2, 3]]]  # the fold's vertices split in the atlas
>>> uv = np.array([[0.05, 0.05], [0.45, 0.05], [0.05, 0.45], [0.45, 0.45],
...                [0.55, 0.95], [0.95, 0.95], [0.55, 0.55], [0.95, 0.55]])
>>> split = np.array([[0, 1, 3], [0, 3, 2], [6, 7, 5], [6, 5, 4]])
>>> pad = surface_padding(unwelded, split, uv, 20, reach=2)
>>> row, col = np.divmod(pad.texel, 20)
>>> beside = (row == 10) & (col == 4)  # one texel above the first chart's top edge (the fold)
>>> np.round(pad.source[beside], 3).tolist()  # 0.0625 beyond the fold: row 8 of the second
[[8.0, 14.0]]
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from imagemap.core.blend import fill_background
from imagemap.scene.bake import rasterize_uv

__all__ = ["MAX_STEPS", "SurfacePadding", "engine_reach", "surface_padding", "walk", "weld"]

#: Faces a walk crosses at most (:func:`walk`). A step of the engine's reach (about 20-36
#: working texels) crosses about that many faces where faces are a texel wide (generated
#: fish at 128^2); a walk still going stops where it is (the padding then a little shorter
#: than asked, never wrong in direction).
MAX_STEPS = 64
#: A barycentric coordinate this far below 0 still counts as inside a face (rounding of a
#: point on an edge).
_INSIDE = 1e-9


def weld(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(welded vertices, welded faces, index of each input vertex's welded vertex).

    A mesh split along its UV seams (one vertex per position and UV) is joined again,
    so that normals and curvature do not see the seams as borders.
    """
    # Rows sorted by their coordinates (np.unique(axis=0) sorts structured rows: 1 s for
    # a 20k-vertex head); equal neighbours after sorting are one vertex.
    order = np.lexsort(vertices.T[::-1])
    ordered = vertices[order]
    first = np.r_[True, np.any(ordered[1:] != ordered[:-1], axis=1)]
    group = np.cumsum(first) - 1
    inverse = np.empty(len(vertices), dtype=np.int64)
    inverse[order] = group
    return ordered[first], inverse[faces], inverse


def engine_reach(patch_sizes) -> int:
    """Texels (of the finest level) beyond a query texel that the engine's windows see.

    A window of width ``k`` at level ``l`` reaches ``k // 2`` texels of that level, each
    ``2**l`` finest texels; one more texel of the level for the Gaussian pyramid's blur
    that made it.

    Examples
    --------
    >>> engine_reach((7, 11, 9))  # 3 | 12 | 20 texels at levels 0 | 1 | 2
    20
    """
    return int(max((k // 2 + 1) * 2**level for level, k in enumerate(patch_sizes)))


def _neighbours(welded_faces: np.ndarray) -> np.ndarray:
    """(F, 3): the face across the edge opposite each corner (-1 at a boundary)."""
    import trimesh  # deferred: start-up (trimesh.graph)

    pairs, edges = trimesh.graph.face_adjacency(faces=welded_faces, return_edges=True)
    across = np.full(welded_faces.shape, -1, dtype=np.int64)
    for side in (0, 1):
        face = pairs[:, side]
        corners = welded_faces[face]
        a = np.argmax(corners == edges[:, :1], axis=1)
        b = np.argmax(corners == edges[:, 1:], axis=1)
        across[face, 3 - a - b] = pairs[:, 1 - side]
    return across


def _barycentric(triangles: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Barycentrics (N, 3) of points in the planes of triangles (N, 3, 3)
    (:func:`trimesh.triangles.points_to_barycentric`; a degenerate triangle gives its
    first corner)."""
    import trimesh  # deferred: start-up

    with np.errstate(divide="ignore", invalid="ignore"):
        bary = trimesh.triangles.points_to_barycentric(triangles, points)
    bad = ~np.all(np.isfinite(bary), axis=1)
    bary[bad] = (1.0, 0.0, 0.0)
    return bary


def walk(
    vertices: np.ndarray,
    faces: np.ndarray,
    face: np.ndarray,
    bary: np.ndarray,
    step: np.ndarray,
    neighbours: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Where straightest paths on a mesh end: (face (N,), barycentrics (N, 3)).

    Each path starts at its face and barycentrics and follows its 3-D ``step`` (in the
    start face's plane; its length is the path's). Across each edge it meets it goes on
    in the face on the other side, the rest of the step turned about the edge into that
    face's plane; at a boundary edge (no face across) it stops; after :data:`MAX_STEPS`
    faces it stops where it is. All paths advance together, one face per pass.

    Parameters
    ----------
    vertices : (V, 3) array
    faces : (F, 3) int array
        Of a welded mesh (faces that share an edge share its vertices).
    face, bary, step : (N,), (N, 3), (N, 3) arrays
    neighbours : (F, 3) int array, optional
        The face across each corner's opposite edge (made when not given).

    Examples
    --------
    Two triangles folded at a right angle along x = 1 (a step of 1.5 along +x from
    (0.5, 0.25, 0) goes 0.5 to the fold, then 1 down the other face):

    >>> v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [1, 0.25, -2.0]])
    >>> f = np.array([[0, 1, 2], [1, 3, 2]])
    >>> end_face, end_bary = walk(v, f, np.array([0]), np.array([[0.5, 0.25, 0.25]]),
    ...                           np.array([[1.5, 0.0, 0.0]]))
    >>> point = np.einsum("nk,nkc->nc", end_bary, v[f[end_face]])
    >>> end_face.tolist(), np.round(point, 6).tolist()
    ([1], [[1.0, 0.25, -1.0]])
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    if neighbours is None:
        neighbours = _neighbours(faces)
    face = np.asarray(face, dtype=np.int64).copy()
    point = np.einsum("nk,nkc->nc", bary, vertices[faces[face]])
    rest = np.asarray(step, dtype=np.float64).copy()
    end = np.asarray(bary, dtype=np.float64).copy()
    active = np.ones(len(face), dtype=bool)
    for _ in range(MAX_STEPS):
        going = np.flatnonzero(active)
        if going.size == 0:
            break
        triangles = vertices[faces[face[going]]]
        here = _barycentric(triangles, point[going])
        there = _barycentric(triangles, point[going] + rest[going])
        inside = np.all(there >= -_INSIDE, axis=1)
        done = going[inside]
        end[done] = there[inside]
        active[done] = False
        going, here, there = going[~inside], here[~inside], there[~inside]
        if going.size == 0:
            break
        rate = there - here
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(rate < 0, np.maximum(here, 0.0) / -rate, np.inf)
        corner = np.argmin(t, axis=1)
        rows = np.arange(len(going))
        fraction = np.clip(t[rows, corner], 0.0, 1.0)
        exit_point = point[going] + fraction[:, None] * rest[going]
        remaining = (1.0 - fraction)[:, None] * rest[going]
        current = face[going]
        across = neighbours[current, corner]
        # Stopped at a boundary (the surface ends): on its edge.
        stop = across < 0
        end[going[stop]] = np.clip(_barycentric(triangles[~inside][stop], exit_point[stop]), 0, 1)
        active[going[stop]] = False
        go = ~stop
        g, current, corner = going[go], current[go], corner[go]
        remaining, exit_point, nxt = remaining[go], exit_point[go], across[go]
        # Unfold: the rest of the step keeps its part along the edge; its part across the
        # edge (out of the current face) goes on into the next face's plane.
        a = vertices[faces[current, (corner + 1) % 3]]
        b = vertices[faces[current, (corner + 2) % 3]]
        along = b - a
        along /= np.maximum(np.linalg.norm(along, axis=1, keepdims=True), 1e-30)
        parallel = np.einsum("nc,nc->n", remaining, along)
        out = np.linalg.norm(remaining - parallel[:, None] * along, axis=1)
        shared = np.any(faces[nxt][:, :, None] == faces[current][:, None, :], axis=2)
        third = vertices[faces[nxt, np.argmin(shared, axis=1)]]
        into = (third - a) - np.einsum("nc,nc->n", third - a, along)[:, None] * along
        into /= np.maximum(np.linalg.norm(into, axis=1, keepdims=True), 1e-30)
        face[g] = nxt
        point[g] = exit_point
        rest[g] = parallel[:, None] * along + out[:, None] * into
    # Still going after MAX_STEPS faces: where the path is.
    left = np.flatnonzero(active)
    if left.size:
        end[left] = np.clip(_barycentric(vertices[faces[face[left]]], point[left]), 0, 1)
    end = np.clip(end, 0.0, 1.0)
    end /= np.maximum(end.sum(axis=1, keepdims=True), 1e-12)
    return face, end


@dataclass
class SurfacePadding:
    """The surface point of every padding texel within a reach of an atlas' charts.

    Attributes
    ----------
    size : int
        The atlas' width and height.
    texel : (N,) int
        The padding texels (flat indices) within the reach.
    face : (N,) int
        The face each one's surface point lies in (of the mesh as given).
    bary : (N, 3) float
        Its barycentrics there.
    source : (N, 2) float
        That point's place in the atlas (row, column; texel centres at integers): in the
        chart of ``face``, across the seam where the walk crossed one.
    mask : (T, T) bool
        The atlas' used texels.
    """

    size: int
    texel: np.ndarray
    face: np.ndarray
    bary: np.ndarray
    source: np.ndarray
    mask: np.ndarray

    def apply(self, values: np.ndarray, mask: np.ndarray) -> np.ndarray:
        """``values`` (T, T) or (T, T, C) with the padding read on the surface.

        Each padding texel within the reach takes the values at its surface point's place
        in the atlas (bilinear over the used texels of ``mask`` only; the nearest used
        texel where none of the four is used); the padding beyond the reach is continued
        from the nearest texel of the rest (:func:`imagemap.core.blend.fill_background`).

        Examples
        --------
        A 1 x 4 atlas: texels 0-1 used, texel 2 padding whose surface point is texel 0's:

        >>> used = np.array([[1, 1, 0, 0]], bool)
        >>> pad = SurfacePadding(4, np.array([2]), np.array([0]), np.ones((1, 3)) / 3,
        ...                      np.array([[0.0, 0.0]]), used)
        >>> pad.apply(np.array([[1.0, 2.0, 0.0, 0.0]]), used).tolist()
        [[1.0, 2.0, 1.0, 1.0]]
        """
        mask = np.asarray(mask, dtype=bool)
        height, width = mask.shape
        out = np.array(values, dtype=np.float32 if values.dtype != np.float64 else np.float64)
        if self.texel.size == 0 or not mask.any():
            return fill_background(out, mask) if mask.any() else out
        flat = out.reshape(height * width, -1)
        row, col = self.source[:, 0], self.source[:, 1]
        r0, c0 = np.floor(row).astype(np.int64), np.floor(col).astype(np.int64)
        fr, fc = row - r0, col - c0
        total = np.zeros(len(row))
        sampled = np.zeros((len(row), flat.shape[1]))
        for dr, dc, weight in ((0, 0, (1 - fr) * (1 - fc)), (0, 1, (1 - fr) * fc),
                               (1, 0, fr * (1 - fc)), (1, 1, fr * fc)):  # fmt: skip
            rr, cc = np.clip(r0 + dr, 0, height - 1), np.clip(c0 + dc, 0, width - 1)
            w = weight * mask[rr, cc]
            total += w
            sampled += w[:, None] * flat[rr * width + cc]
        found = total > 1e-9
        sampled[found] /= total[found, None]
        if not found.all():  # the nearest used texel to the point
            ny, nx = ndimage.distance_transform_edt(~mask, return_distances=False,
                                                    return_indices=True)  # fmt: skip
            rr = np.clip(np.rint(row[~found]), 0, height - 1).astype(np.int64)
            cc = np.clip(np.rint(col[~found]), 0, width - 1).astype(np.int64)
            sampled[~found] = flat[ny[rr, cc] * width + nx[rr, cc]]
        flat[self.texel] = sampled
        known = mask.copy()
        known.flat[self.texel] = True
        return fill_background(out, known)


def surface_padding(
    vertices: np.ndarray,
    faces: np.ndarray,
    uv: np.ndarray,
    size: int,
    reach: float,
    raster: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
) -> SurfacePadding:
    """The surface points continuing the charts into the padding texels within ``reach``.

    Parameters
    ----------
    vertices : (V, 3) array
    faces : (F, 3) int array
    uv : (V, 2) array
        Per-vertex texture coordinates (GL style: v up); a mesh split along its UV seams
        (one vertex per position and UV) is welded for the walk.
    size : int
        The atlas' width and height.
    reach : float
        Padding texels at most this far (texels) from a used texel are placed; 0: none.
    raster : (texel, face, barycentrics), optional
        The atlas' :func:`~imagemap.scene.bake.rasterize_uv` at ``size``, when it was made
        already (:attr:`imagemap.mesh.uvspace.SurfaceMaps.raster`); made here otherwise.

    Returns
    -------
    SurfacePadding
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    uv = np.asarray(uv, dtype=np.float64)
    texel, texel_face, texel_bary = raster if raster is not None else rasterize_uv(uv, faces, size)
    used = np.zeros(size * size, dtype=bool)
    used[texel] = True
    mask = used.reshape(size, size)
    empty = SurfacePadding(size, np.zeros(0, np.int64), np.zeros(0, np.int64),
                           np.zeros((0, 3)), np.zeros((0, 2)), mask)  # fmt: skip
    if reach <= 0 or texel.size == 0 or mask.all():
        return empty
    distance, (ny, nx) = ndimage.distance_transform_edt(~mask, return_indices=True)
    pad = np.flatnonzero((~mask & (distance <= reach)).ravel())
    row, col = np.divmod(pad, size)
    nearest = ny.ravel()[pad] * size + nx.ravel()[pad]
    at = np.searchsorted(texel, nearest)  # rasterize_uv's texels are sorted
    face, start = texel_face[at], texel_bary[at]
    # The UV offset (texel centres) from the nearest used texel, as a 3-D step in its face's
    # plane through the face's affine UV -> 3-D map.
    offset = np.stack([(col - nx.ravel()[pad]) / size, (ny.ravel()[pad] - row) / size], axis=1)
    welded, welded_faces, _ = weld(vertices, faces)
    q = uv[faces[face]]
    p = welded[welded_faces[face]]
    jacobian = np.stack([q[:, 1] - q[:, 0], q[:, 2] - q[:, 0]], axis=2)  # (N, 2, 2)
    det = np.linalg.det(jacobian)
    ok = np.abs(det) > 1e-14
    beta = np.zeros((len(pad), 2))
    beta[ok] = np.linalg.solve(jacobian[ok], offset[ok][..., None])[..., 0]
    step = beta[:, :1] * (p[:, 1] - p[:, 0]) + beta[:, 1:] * (p[:, 2] - p[:, 0])
    end_face, end_bary = walk(welded, welded_faces, face, start, step)
    point_uv = np.einsum("nk,nkc->nc", end_bary, uv[faces[end_face]])
    source = np.stack([(1.0 - point_uv[:, 1]) * size - 0.5, point_uv[:, 0] * size - 0.5], axis=1)
    return SurfacePadding(size, pad, end_face, end_bary, source, mask)
