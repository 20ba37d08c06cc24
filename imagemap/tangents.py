"""Vertex tangents in the MikkTSpace convention (glTF's ``TANGENT``), and the tangent
frames a renderer builds from them inside the faces.

glTF 2.0 reads a normal texture in the tangent frame of the vertex ``TANGENT`` (xyz:
the direction of increasing u, w: the handedness, bitangent = w * normal x tangent);
a file without ``TANGENT`` leaves it to the viewer, which should use MikkTSpace. No
MikkTSpace wheel installs from PyPI, so :func:`mikk_tangents` is MikkTSpace's rule in
NumPy:

- per face, the direction of increasing u (the UV derivative), flipped where the UV
  triangle is mirrored (clockwise), unit length;
- per face corner, that direction projected onto the plane of the corner's vertex
  normal, weighted by the corner's angle (its two edges projected onto the same plane);
- summed over a group of corners, normalised: MikkTSpace's groups, the corners at
  one vertex whose faces share an edge and a UV orientation (:func:`corner_groups`);
  ``w`` is +1 where the UV triangles are counter-clockwise (v up, as trimesh holds
  UVs), else -1.

Vertices are taken as they are, as Blender's MikkTSpace takes them (its
``calc_tangents``; the reference C code first welds vertices of equal position, normal
and UV, which joins groups across duplicated vertices: on projection UVs of a mesh
split along its atlas' seams, 1 % of the corners then differ from Blender's by 18°
or more).

A vertex with two groups (projection UVs at the silhouette, where the far side's
triangles turn over; a mirrored atlas without a seam) has two tangents, as in
MikkTSpace: a file needs a vertex for each (:func:`tangent_split`). Left out of
MikkTSpace's rule: a face with degenerate UVs joins its vertex's counter-clockwise
group (MikkTSpace lets it join any); a group whose faces all have degenerate UVs gets
a unit vector perpendicular to its normal.
``tests/test_blender.py`` checks the result against Blender's ``calc_tangents``.
"""

from __future__ import annotations

import numpy as np

__all__ = ["corner_groups", "corner_tangents", "mikk_tangents", "tangent_frames", "tangent_split"]


def _unit(vectors: np.ndarray) -> np.ndarray:
    length = np.linalg.norm(vectors, axis=-1, keepdims=True)
    return np.where(length > 1e-30, vectors / np.maximum(length, 1e-30), 0.0)


def _project(vectors: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """``vectors`` minus their component along the unit ``normals``, unit length."""
    return _unit(vectors - np.einsum("...i,...i->...", vectors, normals)[..., None] * normals)


def _perpendicular(normals: np.ndarray) -> np.ndarray:
    """A unit vector perpendicular to each unit normal (the axis least along it, projected)."""
    axis = np.eye(3)[np.argmin(np.abs(normals), axis=1)]
    return _project(axis, normals)


def _signed_uv_area(faces: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Twice the signed UV area of each face (> 0: counter-clockwise, v up)."""
    corner_uv = np.asarray(uv, dtype=np.float64)[:, :2][faces]
    d1, d2 = corner_uv[:, 1] - corner_uv[:, 0], corner_uv[:, 2] - corner_uv[:, 0]
    return d1[:, 0] * d2[:, 1] - d2[:, 0] * d1[:, 1]


def corner_groups(faces: np.ndarray, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """MikkTSpace's groups of face corners: group (F, 3) and orientation (F, 3), 1/0.

    The corners at one vertex are one group where their faces share an edge
    (wound the same way) and a UV orientation (1: counter-clockwise, v up), as
    MikkTSpace groups them. A corner of a face with degenerate UVs joins a group of its
    vertex (the counter-clockwise one if there is one), or makes its own.
    """
    from scipy.sparse import coo_matrix  # deferred: start-up (scipy)
    from scipy.sparse.csgraph import connected_components  # deferred: start-up

    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    uv = np.asarray(uv, dtype=np.float64)[:, :2]
    area = _signed_uv_area(faces, uv)
    orient = np.repeat((area > 0).astype(np.int64)[:, None], 3, axis=1)
    # Directed edges k -> k + 1 of every face (edge 3 f + k); a neighbour runs the other way.
    span = max(len(uv), 1)
    start, end = faces, np.roll(faces, -1, axis=1)
    forward = (start * span + end).ravel()
    backward = (end * span + start).ravel()
    order = np.argsort(forward, kind="stable")
    at = np.minimum(np.searchsorted(forward[order], backward), max(len(order) - 1, 0))
    matched = np.flatnonzero(forward[order][at] == backward) if len(order) else np.zeros(0, int)
    other = order[at[matched]]
    f, k = matched // 3, matched % 3
    g, m = other // 3, other % 3
    # Corner (f, k) is the neighbour's corner (g, m + 1), and (f, k + 1) is (g, m).
    links = np.concatenate(
        [
            np.stack([3 * f + k, 3 * g + (m + 1) % 3]),
            np.stack([3 * f + (k + 1) % 3, 3 * g + m]),
        ],
        axis=1,
    )
    flat = orient.ravel()
    usable = np.repeat(area != 0, 3)
    links = links[:, (flat[links[0]] == flat[links[1]]) & usable[links[0]] & usable[links[1]]]
    size = 3 * len(faces)
    graph = coo_matrix((np.ones(links.shape[1], np.int8), (links[0], links[1])), (size, size))
    _, group = connected_components(graph, directed=False)
    # A corner of a face with degenerate UVs joins a group at its vertex (MikkTSpace lets
    # it join any): the counter-clockwise one if there is one.
    vertex = faces.ravel()
    ranked = np.lexsort((1 - flat, ~usable, vertex))  # per vertex: usable, ccw first
    head = np.r_[True, vertex[ranked][1:] != vertex[ranked][:-1]]
    best = np.full(len(uv), -1)
    best[vertex[ranked][head]] = ranked[head]
    degenerate = np.flatnonzero(~usable & usable[np.maximum(best[vertex], 0)] & (best[vertex] >= 0))
    group[degenerate] = group[best[vertex[degenerate]]]
    flat[degenerate] = flat[best[vertex[degenerate]]]
    return group.reshape(-1, 3), flat.reshape(-1, 3)


def tangent_split(faces: np.ndarray, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Faces and the source vertex of each vertex (``origin``), every vertex split into
    one per MikkTSpace group at it (:func:`corner_groups`); unsplit vertices keep
    their index, copies come after them.

    A vertex with two groups has two tangents (projection UVs at the silhouette, where
    the far side's triangles turn over: a ``w`` of +1 and of -1), so a file's
    per-vertex ``TANGENT`` needs a vertex for each.

    Examples
    --------
    >>> points = np.array([[0, 0], [1, 0], [0, 1], [-1, 0]], float)  # two faces, z = 0
    >>> uv = np.abs(points)  # the second face mirrored onto the first
    >>> faces, origin = tangent_split(np.array([[0, 1, 2], [0, 2, 3]]), uv)
    >>> faces.tolist(), origin.tolist()
    ([[0, 1, 2], [4, 5, 3]], [0, 1, 2, 3, 0, 2])
    """
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    group, _ = corner_groups(faces, uv)
    pairs = np.column_stack([faces.ravel(), group.ravel()])
    unique, inverse = np.unique(pairs, axis=0, return_inverse=True)
    origin = unique[:, 0]
    first = np.r_[True, origin[1:] != origin[:-1]]  # each vertex's first group keeps it
    index = np.where(first, origin, len(uv) + np.cumsum(~first) - 1)
    return index[inverse.ravel()].reshape(-1, 3), np.concatenate(
        [np.arange(len(uv)), origin[~first]]
    )


def corner_tangents(
    vertices: np.ndarray, faces: np.ndarray, normals: np.ndarray, uv: np.ndarray
) -> np.ndarray:
    """MikkTSpace's tangent at every face corner (F, 3, 4): unit xyz along increasing
    u, w = handedness (+1: counter-clockwise UVs, v up). Parameters as
    :func:`mikk_tangents`."""
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    normals = _unit(np.asarray(normals, dtype=np.float64))
    uv = np.asarray(uv, dtype=np.float64)[:, :2]
    corners, corner_uv = vertices[faces], uv[faces]
    e1, e2 = corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]
    d1, d2 = corner_uv[:, 1] - corner_uv[:, 0], corner_uv[:, 2] - corner_uv[:, 0]
    area = _signed_uv_area(faces, uv)
    # MikkTSpace's vOs: the derivative of position along u times the UV area, its sign
    # taken off (a mirrored triangle still points along increasing u).
    along_u = _unit((d2[:, 1:2] * e1 - d1[:, 1:2] * e2) * np.where(area > 0, 1.0, -1.0)[:, None])
    usable = (area != 0) & (np.linalg.norm(along_u, axis=1) > 0)

    corner_normal = normals[faces]  # (F, 3, 3)
    tangent = _project(np.repeat(along_u[:, None], 3, axis=1), corner_normal)
    before = _project(np.roll(corners, 1, axis=1) - corners, corner_normal)
    after = _project(np.roll(corners, -1, axis=1) - corners, corner_normal)
    cosine = np.clip(np.einsum("fki,fki->fk", before, after), -1.0, 1.0)
    weight = np.arccos(cosine) * usable[:, None]

    group, orient = corner_groups(faces, uv)
    sums = np.zeros((int(group.max()) + 1 if group.size else 0, 3))
    np.add.at(sums, group.ravel(), (tangent * weight[..., None]).reshape(-1, 3))
    out = np.empty(faces.shape + (4,))
    out[..., :3] = _unit(sums[group])
    missing = np.linalg.norm(out[..., :3], axis=-1) == 0
    out[missing, :3] = _perpendicular(corner_normal[missing])
    out[..., 3] = np.where(orient == 1, 1.0, -1.0)
    return out


def mikk_tangents(
    vertices: np.ndarray, faces: np.ndarray, normals: np.ndarray, uv: np.ndarray
) -> np.ndarray:
    """Per-vertex tangents (V, 4): unit xyz along increasing u, w = handedness (+1/-1).

    A vertex where both UV orientations meet has two tangents: split the mesh with
    :func:`mirror_split` first (else one of its corners' tangents is kept).

    Parameters
    ----------
    vertices : ndarray, (V, 3)
    faces : ndarray, (F, 3)
    normals : ndarray, (V, 3)
        The vertex normals written beside the tangents (need not be unit).
    uv : ndarray, (V, 2)
        Texture coordinates with v up (trimesh's; glTF files hold 1 - v).

    Examples
    --------
    >>> square = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    >>> faces = np.array([[0, 1, 2], [0, 2, 3]])
    >>> up = np.tile([0.0, 0.0, 1.0], (4, 1))
    >>> mikk_tangents(square, faces, up, square[:, :2]).round(6).tolist()[0]
    [1.0, 0.0, 0.0, 1.0]
    >>> mikk_tangents(square, faces, up, square[:, :2] * [-1, 1]).round(6).tolist()[0]
    [-1.0, 0.0, 0.0, -1.0]
    """
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    out = np.zeros((len(vertices), 4))
    out[:, :3] = _perpendicular(_unit(np.asarray(normals, dtype=np.float64)))
    out[:, 3] = 1.0
    out[faces.ravel()] = corner_tangents(vertices, faces, normals, uv).reshape(-1, 4)
    return out


def tangent_frames(
    tangents: np.ndarray,
    normals: np.ndarray,
    faces: np.ndarray,
    face: np.ndarray,
    bary: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The orthonormal tangent frame (t, b, n), (N, 3) each, at surface points.

    As a renderer builds it from the vertex attributes: the normal and the tangent
    interpolated over the face, the tangent made perpendicular to the normal, the
    bitangent ``w * n x t`` (``w`` of the face's first corner).

    Parameters
    ----------
    tangents : ndarray, (F, 3, 4)
        :func:`corner_tangents` (the per-vertex tangents of a split mesh, per corner).
    normals : ndarray, (V, 3)
    faces : ndarray, (F, 3)
    face : ndarray, (N,)
        The face of each point.
    bary : ndarray, (N, 3)
        Its barycentric coordinates.
    """
    face = np.asarray(face, dtype=np.int64)
    corners = np.asarray(faces, dtype=np.int64)[face]
    bary = np.asarray(bary, dtype=np.float64)
    n = _unit(np.einsum("nk,nkc->nc", bary, np.asarray(normals, dtype=np.float64)[corners]))
    at = np.asarray(tangents, dtype=np.float64)[face]  # (N, 3, 4)
    t = _project(np.einsum("nk,nkc->nc", bary, at[..., :3]), n)
    bad = np.linalg.norm(t, axis=1) == 0
    if bad.any():
        t[bad] = _perpendicular(n[bad])
    w = np.where(at[:, 0, 3] < 0, -1.0, 1.0)
    return t, np.cross(n, t) * w[:, None], n
