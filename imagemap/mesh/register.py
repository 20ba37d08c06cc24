"""Mesh examples in ANY UV layout: registered to the query in 3-D, resampled into its atlas.

One module for one job: the registered path's preparation of the examples (rigid fit,
parts, deformation, resampling share the closest-point index they are built on).

The uv-space synthesis (:mod:`imagemap.mesh.uvspace`) needs examples in the query's UV
layout. This module makes them so: each textured mesh example is

1. **registered** to the query (:func:`register_rigid`): both normalised (centroid, RMS
   radius), candidate starts (the identity and the principal axes with every choice of
   signs; the mirrored ones only where the class allows it), each refined by ICP
   (:func:`trimesh.registration.icp`) on a coarse sampling, the one of least symmetric
   residual refined on a finer one, then as a similarity on the nearest pairs only (a
   part one object lacks does not pull the fit, and the scale is fitted);
2. **deformed** smoothly onto the query (:func:`deform`): the example's vertices follow
   the closest-point displacements to and from the query's surface, smoothed by a
   graph-Laplacian solve, stiff first, then less (a cheap non-rigid step:
   :func:`trimesh.registration.nricp_amberg` took 19 s per generated fish);
3. **resampled into the query's atlas** (:func:`resample`): every used texel of the
   query's atlas is a surface point; its closest point on the deformed example is a face
   and barycentrics of the example, so an example UV: the example's texture is sampled
   there (bilinear, at the output texture's size). The same face and barycentrics on the
   *rigidly* registered example give the example's own surface guides there: its
   position (where the example's point is, against the query's: the shape's
   disagreement), its normal and its curvature.

The examples then share the query's layout and the uv-space synthesis runs on them as
it does on scanned heads: :func:`registered_examples` gives :class:`RegisteredExample`
objects that :func:`imagemap.mesh.uvspace.colorize_uv` takes as they are.

Examples
--------
A box turned, scaled and moved is brought back onto itself:

>>> import trimesh
>>> box = trimesh.creation.box(extents=(3.0, 2.0, 1.0)).subdivide().subdivide()
>>> turn = trimesh.transformations.rotation_matrix(0.3, [0, 0, 1]) @ np.diag([2, 2, 2, 1.0])
>>> fit = register_rigid(box.copy().apply_transform(turn), box)
>>> fit.mirrored, bool(np.abs(fit.vertices - box.vertices).max() < 0.05)
(False, True)
"""

from __future__ import annotations

import itertools
import logging
import time
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import trimesh
from scipy import sparse
from scipy.sparse.linalg import factorized
from scipy.spatial import cKDTree

from imagemap.core.blend import fill_background
from imagemap.errors import InputError
from imagemap.mesh.padding import weld
from imagemap.mesh.uvspace import (
    SurfaceMaps,
    UVExample,
    _vertex_normals,
    vertex_curvature,
)
from imagemap.scene.bake import rasterize_uv
from imagemap.scene.views import surface_colours

__all__ = [
    "MeshSurface",
    "Registration",
    "RegisteredExample",
    "deform",
    "refine_rigid",
    "register_rigid",
    "registered_examples",
    "resample",
]

log = logging.getLogger("imagemap")

#: Surface samples for the candidates' coarse ICP (each start is refined on these; 300
#: chose the same fish as 800 with the same residuals to 1e-4, at 0.6 of the time) ...
COARSE_SAMPLES = 300
#: ... and for the chosen start's fine ICP, the residual and the deformation's targets.
FINE_SAMPLES = 6000
#: ICP iterations per candidate (coarse) and for the chosen one (fine).
COARSE_ITERATIONS = 8
FINE_ITERATIONS = 30
#: The fine fit is then refined as a similarity (rotation, scale, translation) on the closest
#: pairs both ways, this share of each kept (the nearest): parts one surface has and the
#: other lacks (a longer neck, a mouth bag) do not pull the fit, and the scale is fitted
#: rather than taken from the RMS radii of unequal extents. FFHQ-UV's teaser3 onto the
#: FLAME head: mean 3-D distance of points of one UV (the heads share a layout) 0.143 ->
#: 0.105 RMS radii (on all 6000 samples 0.111; the scale fixed 0.130; keeping 0.5 0.112).
TRIM_SHARE = 0.7
#: Samples of that refinement (the fine ones' first): a third of the time of all 6000 (on
#: every second one, 0.119: the fit creeps, and stops near, not on, an optimum) ...
TRIM_SAMPLES = 2000
#: ... its iterations at most, and the largest change of a step's matrix that ends it.
TRIM_ITERATIONS = 20
TRIM_TOLERANCE = 1e-3
#: A mirrored or turned start replaces the identity (the meshes as posed) only when its
#: residual is below this share of the identity's: objects of one class are usually posed
#: alike, and a symmetric body fits its mirror image nearly as well (generated fish:
#: 1.00-1.03 of the identity's residual), which would swap its flanks for nothing.
TURN_GAIN = 0.8
#: Laplacian stiffness of the deformation's passes (in vertex hops squared: ~sqrt of it
#: hops of smoothing), stiff first: the body moves as a whole before its parts do.
STIFFNESS = (400.0, 100.0, 25.0, 6.0)
#: Closest-point displacements longer than this (in RMS radii) are not followed: a part
#: the other object lacks (a fin) does not pull the surface across the body.
PULL_DISTANCE = 0.25
#: A pull is followed only where the two surfaces face alike (cosine of their normals above
#: this, 60 degrees): a head's mouth bag and eye sockets (inner surfaces, facing every way)
#: are not pulled out onto the query's face (FFHQ-UV's FLAME head from teaser3: 8.29 ->
#: 8.07 ΔE00 of the transfer with the main part re-centred, 6.48 -> 6.46 without).
NORMAL_AGREEMENT = 0.5
#: Two connected parts (a fin, an eye) correspond when their centroids (in RMS radii of
#: the query) plus the log of their sizes' ratio differ by less than this: generated fish
#: (body, tail, three fins, eye) match part for part at 0.1-0.3; a part of no match
#: (cost above this) is searched on the whole example.
PART_MATCH_COST = 0.6
#: Candidate faces examined per point by the closest-point search (nearest samples' faces;
#: with samples near every face's corners, 4 finds the same faces on the tests' sheets as
#: 8 did, at half the time of a fish's resample).
CLOSEST_CANDIDATES = 4
#: Dense samples per face of the closest-point search (so a point's nearest samples lie on
#: or beside its closest face).
SAMPLES_PER_FACE = 6


@dataclass
class Registration:
    """A mesh example registered to the query.

    Attributes
    ----------
    matrix : (4, 4) array
        Example world -> query world (similarity: rotation, uniform scale, translation;
        a reflection when ``mirrored``).
    mirrored : bool
        The matrix reflects (its determinant is negative).
    residual : float
        Symmetric mean closest-sample distance after the rigid fit, in RMS radii of the
        query: the shapes' agreement, by which the examples are chosen.
    vertices : (V, 3) array
        The example's vertices rigidly registered (query world).
    deformed : (V, 3) array
        The same after the smooth deformation onto the query (query world).
    faces : (F, 3) int array
        The example's faces, wound outwards again when the matrix reflects.
    """

    matrix: np.ndarray
    mirrored: bool
    residual: float
    vertices: np.ndarray
    deformed: np.ndarray
    faces: np.ndarray


def _corners_and_areas(
    vertices: np.ndarray, faces: np.ndarray, surface: bool = True
) -> tuple[np.ndarray, np.ndarray]:
    """Each face's corners (F, 3, 3) and area (F,); with ``surface``, an InputError when
    every face has zero area."""
    corners = vertices[faces]
    areas = 0.5 * np.linalg.norm(
        np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1
    )
    if surface and not areas.sum() > 0:
        raise InputError("the mesh has no surface (every face has zero area)")
    return corners, areas


def surface_frame(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, float]:
    """(centroid, RMS radius) of a mesh's surface, exact (area-weighted moments).

    Examples
    --------
    >>> import trimesh
    >>> sphere = trimesh.creation.icosphere(subdivisions=4, radius=2.0)
    >>> centre, radius = surface_frame(sphere.vertices + 1.0, sphere.faces)
    >>> np.round(centre, 6).tolist(), round(radius, 2)
    ([1.0, 1.0, 1.0], 2.0)
    """
    corners, areas = _corners_and_areas(vertices, faces)
    total = areas.sum()
    centre = (areas[:, None] * corners.mean(axis=1)).sum(axis=0) / total
    local = corners - centre
    # E|x|^2 over a triangle = (sum |v_i|^2 + |sum v_i|^2) / 12.
    second = (np.sum(local**2, axis=(1, 2)) + np.sum(local.sum(axis=1) ** 2, axis=1)) / 12.0
    radius = float(np.sqrt((areas * second).sum() / total))
    return centre, radius if radius > 0 else 1.0


def _frame(points: np.ndarray) -> tuple[np.ndarray, float]:
    """(centroid, RMS radius) of points (radius 1 for a single point)."""
    centre = points.mean(axis=0)
    radius = float(np.sqrt(np.mean(np.sum((points - centre) ** 2, axis=1))))
    return centre, radius if radius > 0 else 1.0


def surface_samples(
    vertices: np.ndarray, faces: np.ndarray, count: int, seed: int = 0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(points (N, 3), face (N,), barycentrics (N, 3)): area-uniform random surface samples.

    Examples
    --------
    >>> tri = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    >>> points, face, bary = surface_samples(tri, np.array([[0, 1, 2]]), 5)
    >>> points.shape, bool(np.allclose(bary.sum(axis=1), 1.0)), bool((points[:, 2] == 0).all())
    ((5, 3), True, True)
    """
    corners, areas = _corners_and_areas(vertices, faces)
    total = areas.sum()
    rng = np.random.default_rng(seed)
    face = rng.choice(len(faces), size=count, p=areas / total)
    r1, r2 = np.sqrt(rng.random(count)), rng.random(count)
    bary = np.stack([1.0 - r1, r1 * (1.0 - r2), r1 * r2], axis=1)
    points = np.einsum("nk,nkc->nc", bary, corners[face])
    return points, face, bary


def _read_only(array: np.ndarray) -> np.ndarray:
    """A read-only view of ``array`` (kept in a cache, shared by every caller)."""
    view = array.view()
    view.flags.writeable = False
    return view


class MeshSurface:
    """A mesh's arrays and what the registered path reads of them, each made once.

    The registered path reads the same things of the query for every example: its fine
    samples and surface frame for each rigid fit, its connected parts, their frames and
    closest-point indices for each part matching and deformation, and its atlas' texel
    points at each size for each resampling (:func:`resample`: ``rasterize_uv``, a weld
    and the points, 0.35 s for a head's 1024^2 atlas); and of an example, its samples
    and frame for its rigid fit and again for its refinement. A MeshSurface makes each on
    first use and keeps it (as trimesh's cached properties do), so that every example
    and every size of one query share them; the values are those made each time before,
    so the same bytes come out. Its arrays are read-only views: the mesh must not change
    while it is in use.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        Or any object with ``vertices`` and ``faces`` (and per-vertex ``visual.uv`` for
        :meth:`atlas_points`).

    Examples
    --------
    >>> import trimesh
    >>> sheet = trimesh.creation.box(extents=(2.0, 1.0, 0.2)).subdivide()
    >>> sheet.visual = trimesh.visual.TextureVisuals(uv=sheet.vertices[:, :2] / [2, 1] + 0.5)
    >>> surface = MeshSurface(sheet)
    >>> surface.atlas_points(16) is surface.atlas_points(16), MeshSurface.of(surface) is surface
    (True, True)
    """

    def __init__(self, mesh) -> None:
        self.mesh = mesh
        self.vertices = _read_only(np.asarray(mesh.vertices, dtype=np.float64))
        self.faces = _read_only(np.asarray(mesh.faces, dtype=np.int64))
        self._samples: dict[tuple[int, int], tuple] = {}
        self._atlas: dict[int, tuple] = {}
        self._indices: dict[tuple[int, int], SurfaceIndex] = {}

    @classmethod
    def of(cls, mesh) -> MeshSurface:
        """``mesh`` itself when it is a MeshSurface, else a new one of it."""
        return mesh if isinstance(mesh, cls) else cls(mesh)

    @cached_property
    def frame(self) -> tuple[np.ndarray, float]:
        """(centroid, RMS radius) of the surface (:func:`surface_frame`)."""
        return surface_frame(self.vertices, self.faces)

    @cached_property
    def vertex_frame(self) -> tuple[np.ndarray, float]:
        """(centroid, RMS radius) of the vertices."""
        return _frame(self.vertices)

    def samples(self, count: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:func:`surface_samples` of the surface (count, seed), made once."""
        key = (int(count), int(seed))
        if key not in self._samples:
            made = surface_samples(self.vertices, self.faces, count, seed)
            self._samples[key] = tuple(_read_only(a) for a in made)
        return self._samples[key]

    @cached_property
    def part_labels(self) -> np.ndarray:
        """Each face's connected part (:func:`_part_labels`)."""
        return _read_only(_part_labels(self.vertices, self.faces))

    @cached_property
    def part_frames(self) -> tuple[np.ndarray, np.ndarray]:
        """(area-weighted centroid, sqrt of the area) of each part (:func:`_part_frames`)."""
        return _part_frames(self.vertices, self.faces, self.part_labels)

    @cached_property
    def face_normals(self) -> np.ndarray:
        """Unit face normals."""
        return _read_only(_face_normals(self.vertices, self.faces))

    def part_index(self, part: int, seed: int) -> SurfaceIndex:
        """The closest-point index of one connected part's faces (:class:`SurfaceIndex`;
        ``part`` -1: of every face)."""
        key = (int(part), int(seed))
        if key not in self._indices:
            every = np.arange(len(self.faces))
            subset = every if part < 0 else np.flatnonzero(self.part_labels == part)
            self._indices[key] = SurfaceIndex(self.vertices, self.faces[subset], seed)
        return self._indices[key]

    def release_indices(self) -> None:
        """Let go of the parts' closest-point indices (made again when asked for)."""
        self._indices.clear()

    def atlas_points(self, size: int) -> tuple[np.ndarray, float, tuple]:
        """(centroid, RMS radius, (texel, face, point)) of the used texels of the mesh's
        ``size``^2 atlas: each texel's flat index, face and surface point (on the welded
        surface, as :func:`imagemap.mesh.uvspace.surface_maps` has them), made once per
        size.

        Raises
        ------
        InputError
            When the UVs cover no texel.
        """
        if size not in self._atlas:
            uv = np.asarray(self.mesh.visual.uv, dtype=np.float64)
            texel, face, bary = rasterize_uv(uv, self.faces, size)
            if texel.size == 0:
                raise InputError("the mesh's UV layout covers no texel")
            welded, welded_faces, _ = weld(self.vertices, self.faces)
            points = np.einsum("nk,nkc->nc", bary, welded[welded_faces[face]])
            centre, radius = _frame(points)
            arrays = tuple(_read_only(a) for a in (texel, face, points))
            self._atlas[size] = (_read_only(centre), radius, arrays)
        return self._atlas[size]


def _residual(a: np.ndarray, b: np.ndarray, tree_b: cKDTree | None = None) -> float:
    """Symmetric mean nearest-neighbour distance between two point sets."""
    tree_b = tree_b or cKDTree(b)
    there = tree_b.query(a)[0]
    back = cKDTree(a).query(b)[0]
    return float(0.5 * (there.mean() + back.mean()))


def _starts(source: np.ndarray, target: np.ndarray, mirror: bool) -> list[np.ndarray]:
    """Candidate rotations (3, 3) of normalised source points onto normalised target
    points: the identity, then the principal axes matched with every choice of signs
    (the reflections only with ``mirror``)."""
    starts = [np.eye(3)]
    _, _, axes_s = np.linalg.svd(source, full_matrices=False)
    _, _, axes_t = np.linalg.svd(target, full_matrices=False)
    for signs in itertools.product((1.0, -1.0), repeat=3):
        rotation = axes_t.T @ np.diag(signs) @ axes_s
        if np.linalg.det(rotation) < 0 and not mirror:
            continue
        starts.append(rotation)
    if mirror:
        starts.append(np.diag([1.0, 1.0, -1.0]))  # the identity's mirror (flanks swapped)
    return starts


def _apply(matrix: np.ndarray, points: np.ndarray) -> np.ndarray:
    return points @ matrix[:3, :3].T + matrix[:3, 3]


def _trimmed_similarity(
    matrix: np.ndarray, source: np.ndarray, moved: np.ndarray, target: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """``matrix`` (source -> target, ``moved`` its image of ``source``) refined by a
    similarity on the nearest :data:`TRIM_SHARE` of the closest pairs, both ways
    (:data:`TRIM_ITERATIONS`); a reflection in ``matrix`` is kept (each step is proper)."""
    every = source
    source, moved, target = source[:TRIM_SAMPLES], moved[:TRIM_SAMPLES], target[:TRIM_SAMPLES]
    tree = cKDTree(target)
    for _ in range(TRIM_ITERATIONS):
        there, j = tree.query(moved)
        back, i = cKDTree(moved).query(target)
        near, near_back = (
            there <= np.quantile(there, TRIM_SHARE),
            back <= np.quantile(back, TRIM_SHARE),
        )
        step, _, _ = trimesh.registration.procrustes(
            np.r_[moved[near], moved[i[near_back]]], np.r_[target[j[near]], target[near_back]],
            reflection=False, scale=True,
        )  # fmt: skip
        matrix = step @ matrix
        moved = _apply(matrix, source)
        if np.abs(step - np.eye(4)).max() < TRIM_TOLERANCE:
            break
    return matrix, _apply(matrix, every)


def _normalised(example, query, seed: int) -> tuple:
    """(source, target, e_frame, q_frame): both meshes' fine samples in their own normalised
    frames (centroid, RMS radius of the surface), with those frames (each a mesh or its
    :class:`MeshSurface`, whose samples and frame are made once)."""
    e_surface, q_surface = MeshSurface.of(example), MeshSurface.of(query)
    # The same seed for both: a mesh registered to itself is its own samples' fit (identity).
    e_fine = e_surface.samples(FINE_SAMPLES, seed)[0]
    q_fine = q_surface.samples(FINE_SAMPLES, seed)[0]
    e_frame = e_surface.frame
    q_frame = q_surface.frame
    source = (e_fine - e_frame[0]) / e_frame[1]
    target = (q_fine - q_frame[0]) / q_frame[1]
    return source, target, e_frame, q_frame


def _registration(matrix, residual, example, e_frame, q_frame) -> Registration:
    """The Registration of a fit in the normalised frames (``matrix`` maps the example's
    normalised samples onto the query's)."""
    (e_centre, e_radius), (q_centre, q_radius) = e_frame, q_frame
    if isinstance(example, MeshSurface):
        example = example.mesh  # its own arrays (the surface's are read-only views)
    # y = q_radius (L (x - e_centre) / e_radius + b) + q_centre in world units.
    linear = matrix[:3, :3]
    full = np.eye(4)
    full[:3, :3] = linear * (q_radius / e_radius)
    full[:3, 3] = q_radius * matrix[:3, 3] + q_centre - full[:3, :3] @ e_centre
    mirrored = bool(np.linalg.det(linear) < 0)
    vertices = _apply(full, np.asarray(example.vertices, dtype=np.float64))
    e_faces = np.asarray(example.faces, dtype=np.int64)
    faces = e_faces[:, ::-1].copy() if mirrored else e_faces
    return Registration(full, mirrored, residual, vertices, vertices.copy(), faces)


def refine_rigid(registration: Registration, example, query, seed: int = 0) -> Registration:
    """A rigid fit (:func:`register_rigid` with ``refine=False``) refined as a similarity on
    the nearest pairs (:data:`TRIM_SHARE`), as ``refine=True`` does."""
    source, target, e_frame, q_frame = _normalised(example, query, seed)
    (e_centre, e_radius), (q_centre, q_radius) = e_frame, q_frame
    full = registration.matrix
    matrix = np.eye(4)
    matrix[:3, :3] = full[:3, :3] * (e_radius / q_radius)
    matrix[:3, 3] = (full[:3, :3] @ e_centre + full[:3, 3] - q_centre) / q_radius
    matrix, moved = _trimmed_similarity(matrix, source, _apply(matrix, source), target)
    return _registration(matrix, _residual(moved, target), example, e_frame, q_frame)


def register_rigid(
    example, query, mirror: bool = False, seed: int = 0, refine: bool = True
) -> Registration:
    """The rigid (similarity) registration of a mesh example onto the query.

    Parameters
    ----------
    example, query : trimesh.Trimesh
    mirror : bool
        Reflections are candidates too (a class whose two sides are mirror images).
    seed : int
        Of the surface samples (same seed, same registration).
    refine : bool
        Refine the ICP fit as a similarity on the nearest pairs (below; :func:`refine_rigid`
        does it later).

    Returns
    -------
    Registration
        ``deformed`` is the rigid fit itself (see :func:`deform`).

    Notes
    -----
    After ICP (rotation and translation, the scale from the RMS radii), the fit is refined
    as a similarity on the nearest :data:`TRIM_SHARE` of the closest pairs both ways: a
    longer neck or a mouth bag neither moves it nor sets its scale.
    """
    source, target, e_frame, q_frame = _normalised(example, query, seed)
    coarse_s, coarse_t = source[:COARSE_SAMPLES], target[:COARSE_SAMPLES]
    tree_coarse = cKDTree(coarse_t)
    fits = []
    for rotation in _starts(source, target, mirror):
        initial = np.eye(4)
        initial[:3, :3] = rotation
        matrix, moved, _ = trimesh.registration.icp(
            coarse_s, coarse_t, initial=initial, max_iterations=COARSE_ITERATIONS,
            reflection=False, scale=False,
        )  # fmt: skip
        fits.append((_residual(moved, coarse_t, tree_coarse), matrix))
    best = int(np.argmin([r for r, _ in fits]))
    if fits[0][0] * TURN_GAIN <= fits[best][0]:
        best = 0  # as posed, unless another start fits clearly better
    matrix, moved, _ = trimesh.registration.icp(
        source, target, initial=fits[best][1], max_iterations=FINE_ITERATIONS,
        reflection=False, scale=False,
    )  # fmt: skip
    if refine:
        matrix, moved = _trimmed_similarity(matrix, source, moved, target)
    return _registration(matrix, _residual(moved, target), example, e_frame, q_frame)


def _face_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Unit face normals (0 for a face of no area)."""
    corners = vertices[faces]
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    return normals / np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-30)


def _laplacian(faces: np.ndarray, count: int) -> sparse.csr_matrix:
    """The uniform graph Laplacian (degree minus adjacency) of a mesh's edges."""
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    i, j = np.r_[edges[:, 0], edges[:, 1]], np.r_[edges[:, 1], edges[:, 0]]
    adjacency = sparse.csr_matrix((np.ones(len(i)), (i, j)), shape=(count, count))
    adjacency.data[:] = 1.0  # each edge once, whatever number of faces share it
    degree = np.asarray(adjacency.sum(axis=1)).ravel()
    return (sparse.diags(degree) - adjacency).tocsc()


@dataclass
class Parts:
    """Connected parts of the query and of a registered example, matched part for part.

    Attributes
    ----------
    query : (F_q,) int
        Each query face's part.
    example : (F_e,) int
        Each example face's part.
    pairs : dict
        Query part -> the example part it corresponds to (parts without one left out).
    """

    query: np.ndarray
    example: np.ndarray
    pairs: dict


def _part_labels(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Each face's connected part (faces sharing an edge of the welded mesh)."""
    _, welded_faces, _ = weld(vertices, faces)
    adjacency = trimesh.graph.face_adjacency(welded_faces)
    return trimesh.graph.connected_component_labels(adjacency, node_count=len(faces))


def _part_frames(vertices, faces, labels) -> tuple[np.ndarray, np.ndarray]:
    """(area-weighted centroid (P, 3), sqrt of the area (P,)) of each part."""
    corners, areas = _corners_and_areas(vertices, faces, surface=False)
    count = int(labels.max()) + 1
    total = np.bincount(labels, weights=areas, minlength=count)
    centres = np.stack(
        [np.bincount(labels, weights=areas * corners.mean(axis=1)[:, k], minlength=count)
         for k in range(3)], axis=1,
    ) / np.maximum(total, 1e-30)[:, None]  # fmt: skip
    return centres, np.sqrt(total)


def match_parts(registration: Registration, query) -> Parts:
    """The example's connected parts matched to the query's (:data:`PART_MATCH_COST`).

    One-to-one (:func:`scipy.optimize.linear_sum_assignment`) on the distance of the parts'
    centroids after the rigid fit, in RMS radii of the query, plus the absolute log of
    their sizes' ratio. A mesh of one part matches it to the other's largest. ``query``
    is the mesh or its :class:`MeshSurface` (whose parts are then found once).
    """
    from scipy.optimize import linear_sum_assignment  # deferred: start-up (scipy.optimize)

    surface = MeshSurface.of(query)
    q_labels = surface.part_labels
    e_labels = _part_labels(registration.vertices, registration.faces)
    q_centres, q_sizes = surface.part_frames
    e_centres, e_sizes = _part_frames(registration.vertices, registration.faces, e_labels)
    _, radius = surface.vertex_frame
    cost = np.linalg.norm(q_centres[:, None] - e_centres[None], axis=2) / radius + np.abs(
        np.log(np.maximum(q_sizes[:, None], 1e-30) / np.maximum(e_sizes[None], 1e-30))
    )
    rows, cols = linear_sum_assignment(cost)
    pairs = {
        int(r): int(c) for r, c in zip(rows, cols, strict=True) if cost[r, c] < PART_MATCH_COST
    }
    if not pairs:
        pairs = {int(np.argmax(q_sizes)): int(np.argmax(e_sizes))}
    return Parts(q_labels, e_labels, pairs)


def deform(registration: Registration, query, seed: int = 0, parts: Parts | None = None):
    """The registered example deformed smoothly onto the query's surface.

    Each matched part of the example but its largest (:func:`match_parts`: an eye onto
    the query's eye, a fin onto its fin; the body stays as the rigid fit put it) is first
    moved and scaled onto its query part (centroid and size). Then each pass moves every
    (welded) vertex by the smooth field that best follows the displacements to the query:
    each vertex's to its closest query point and each query sample's from its closest
    example point (within the matched parts, within :data:`PULL_DISTANCE`, and where the
    two surfaces face alike, :data:`NORMAL_AGREEMENT`), smoothed by ``(W + s L) x = W d``
    (``L`` the graph Laplacian, ``s`` from :data:`STIFFNESS`).

    ``query`` is the mesh or its :class:`MeshSurface` (whose samples, normals and parts'
    closest-point indices then serve every example); ``parts`` the example's
    (:func:`match_parts`), found here when not given.

    Returns
    -------
    Registration
        With ``deformed`` set (``vertices``, the rigid fit, kept).
    """
    surface = MeshSurface.of(query)
    parts = parts or match_parts(registration, surface)
    q_vertices, q_faces = surface.vertices, surface.faces
    targets, target_face, _ = surface.samples(FINE_SAMPLES, seed + 2)
    target_part = parts.query[target_face]
    _, q_radius = _frame(targets)
    pull = PULL_DISTANCE * q_radius
    welded, welded_faces, index = weld(registration.vertices, registration.faces)
    count = len(welded)
    vertex_part = np.full(count, -1, dtype=np.int64)
    for k in range(3):
        vertex_part[welded_faces[:, k]] = parts.example
    # The query's parts as the surface has them (made once for every example) when they
    # are its own, as they are when found by match_parts.
    own_parts = np.array_equal(parts.query, surface.part_labels)
    q_centres, q_sizes = (
        surface.part_frames if own_parts else _part_frames(q_vertices, q_faces, parts.query)
    )
    e_centres, e_sizes = _part_frames(registration.vertices, registration.faces, parts.example)
    points = welded.copy()
    # The example's largest part (a body, a head) stays where the rigid fit put it: that fit
    # is its registration, and centroids and areas compare badly where the surfaces cover
    # different extents (FFHQ-UV's teaser3 onto the FLAME head, whose neck is shorter:
    # moved 0.14 RMS radii by them; median UV error against the heads' shared layout 49
    # texels of 1024, 23 kept in place).
    main = int(np.argmax(e_sizes))
    for q_part, e_part in parts.pairs.items():
        if e_part == main:
            continue
        here = vertex_part == e_part
        scale = q_sizes[q_part] / max(e_sizes[e_part], 1e-30)
        points[here] = q_centres[q_part] + scale * (points[here] - e_centres[e_part])
    # (example part, query part) searched together; unmatched example parts: everywhere.
    groups = [(e, q) for q, e in parts.pairs.items()]
    matched = set(parts.pairs.values())
    if np.any(~np.isin(parts.example, list(matched))):
        groups.append((-1, -1))
    everything = np.arange(len(q_faces))
    laplacian = _laplacian(welded_faces, count)
    indices: dict[int, SurfaceIndex] = {}  # the query's parts' (-1: all faces)
    q_normals = surface.face_normals
    target_normal = q_normals[target_face]
    for stiffness in STIFFNESS:
        pulls = np.zeros_like(points)
        weight = np.zeros(count)
        e_normals = _vertex_normals(points, welded_faces)
        for e_part, q_part in groups:
            if e_part >= 0:
                v_index = np.flatnonzero(vertex_part == e_part)
                e_subset = np.flatnonzero(parts.example == e_part)
                q_subset = np.flatnonzero(parts.query == q_part)
                t_points = targets[target_part == q_part]
            else:
                v_index = np.flatnonzero(~np.isin(vertex_part, list(matched)))
                e_subset = np.flatnonzero(~np.isin(parts.example, list(matched)))
                q_subset, t_points = everything, targets[:0]
            if v_index.size == 0 or q_subset.size == 0:
                continue
            # Each vertex towards its closest point of the query part (exact: none on
            # the same surface) ...
            if q_part not in indices:
                indices[q_part] = (
                    surface.part_index(q_part, seed)
                    if own_parts
                    else SurfaceIndex(q_vertices, q_faces[q_subset], seed)
                )
            f, b, d = indices[q_part].closest(points[v_index])
            facing = np.einsum("nc,nc->n", e_normals[v_index], q_normals[q_subset[f]])
            near = (d < pull) & (facing > NORMAL_AGREEMENT)
            there = np.einsum("nk,nkc->nc", b, q_vertices[q_faces[q_subset[f]]])
            pulls[v_index[near]] += there[near] - points[v_index[near]]
            weight[v_index[near]] += 1.0
            if t_points.size == 0 or e_subset.size == 0:
                continue
            # ... and each query sample's closest example point towards it, spread over
            # that face's corners by their barycentrics.
            f, b, d = closest_points(points, welded_faces[e_subset], t_points, seed)
            corners = welded_faces[e_subset[f]]
            e_normal = np.einsum("nk,nkc->nc", b, e_normals[corners])
            facing = np.einsum("nc,nc->n", e_normal, target_normal[target_part == q_part])
            keep = (d < pull) & (facing > NORMAL_AGREEMENT * np.linalg.norm(e_normal, axis=1))
            corners = corners[keep]
            here = np.einsum("nk,nkc->nc", b[keep], points[corners])
            for k in range(3):
                np.add.at(pulls, corners[:, k], b[keep, k, None] * (t_points[keep] - here))
                np.add.at(weight, corners[:, k], b[keep, k])
        solve = factorized((sparse.diags(weight) + stiffness * laplacian).tocsc())
        move = np.stack([solve(pulls[:, k]) for k in range(3)], axis=1)
        points = points + move
    return Registration(
        registration.matrix,
        registration.mirrored,
        registration.residual,
        registration.vertices,
        points[index],
        registration.faces,
    )


class SurfaceIndex:
    """A mesh's faces ready for closest-point queries (:meth:`closest`).

    The candidate faces of a point are those of its :data:`CLOSEST_CANDIDATES` nearest
    dense surface samples (each face has samples at its centroid and near its corners
    too, so that a small or thin face is never without one); the closest point on each
    distinct candidate triangle is exact (:func:`trimesh.triangles.closest_point`).
    """

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, seed: int = 0):
        self.vertices, self.faces = vertices, faces
        count = max(len(faces) * SAMPLES_PER_FACE, 64)
        samples, sample_face, _ = surface_samples(vertices, faces, count, seed)
        every = np.arange(len(faces))
        # Corners drawn a tenth towards the centroid: distinct samples, each of its face.
        corners, centroids = vertices[faces], vertices[faces].mean(axis=1)
        inset = 0.9 * corners + 0.1 * centroids[:, None, :]
        self.sample_face = np.r_[sample_face, every, np.repeat(every, 3)]
        self.tree = cKDTree(np.r_[samples, centroids, inset.reshape(-1, 3)])

    def closest(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(face (N,), barycentrics (N, 3), distance (N,)) of each point's closest point."""
        k = min(CLOSEST_CANDIDATES, len(self.sample_face))
        _, nearest = self.tree.query(points, k=k)
        candidates = np.sort(self.sample_face[nearest.reshape(len(points), k)], axis=1)
        # Each distinct candidate face of a point once (several samples share a face).
        fresh = np.ones(candidates.shape, dtype=bool)
        fresh[:, 1:] = candidates[:, 1:] != candidates[:, :-1]
        rows, cols = np.nonzero(fresh)
        triangles = self.vertices[self.faces[candidates[rows, cols]]]
        closest = trimesh.triangles.closest_point(triangles, points[rows])
        distance = np.full(candidates.shape, np.inf)
        distance[rows, cols] = np.linalg.norm(closest - points[rows], axis=1)
        found = np.full(candidates.shape + (3,), np.nan)
        found[rows, cols] = closest
        pick = np.argmin(distance, axis=1)
        every = np.arange(len(points))
        face = candidates[every, pick]
        chosen = found[every, pick]
        bary = trimesh.triangles.points_to_barycentric(self.vertices[self.faces[face]], chosen)
        bary = np.clip(bary, 0.0, 1.0)
        bary /= np.maximum(bary.sum(axis=1, keepdims=True), 1e-12)
        return face, bary, distance[every, pick]


def closest_points(
    vertices: np.ndarray, faces: np.ndarray, points: np.ndarray, seed: int = 0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(face (N,), barycentrics (N, 3), distance (N,)) of each point's closest surface point
    (:class:`SurfaceIndex`).

    Examples
    --------
    >>> tri = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    >>> face, bary, dist = closest_points(tri, np.array([[0, 1, 2]]), np.array([[0.25, 0.25, 2.0]]))
    >>> face.tolist(), np.round(bary, 3).tolist(), np.round(dist, 3).tolist()
    ([0], [[0.5, 0.25, 0.25]], [2.0])
    """
    return SurfaceIndex(vertices, faces, seed).closest(points)


@dataclass
class Resampled:
    """One example in the query's atlas at one size.

    Attributes
    ----------
    colour : (T, T, 3) float32 or None
        The example's texture at each used texel's corresponding point; padded (None when
        only the guides were asked for).
    maps : SurfaceMaps
        The example's guides at each texel (position in the query's normalised frame);
        its mask is the query's used texels.
    distance : (T, T) float32
        Each used texel's distance to its corresponding point (on the deformed example),
        in RMS radii of the query; 0 outside the charts.
    correspondence : (texel (N,), face (N,), barycentrics (N, 3)) or None
        Each used texel's (flat index) surface point on the example: a face of its own
        and barycentrics in its own winding, where its colour was sampled (its PBR maps
        are carried the same way, :func:`imagemap.mesh.maps.registered_maps`).
    """

    colour: np.ndarray | None
    maps: SurfaceMaps
    distance: np.ndarray
    correspondence: tuple | None = None


class RegisteredSurface:
    """A registered example as :func:`resample` reads it at every size, each part made once.

    Its parts matched to the query's (:func:`match_parts`), the closest-point index of each
    of its deformed parts, and its rigid fit's welded surface with normals and curvature
    (the guides): the same at the output size and at the engine's working size, so made
    on first use and kept.

    Parameters
    ----------
    registration : Registration
        The example's registration, deformed (:func:`deform`).
    query : MeshSurface
    seed : int
    parts : Parts, optional
        The example's parts matched to the query's (found here when not given).
    """

    def __init__(
        self, registration: Registration, query: MeshSurface, seed: int = 0, parts=None
    ) -> None:
        self.registration = registration
        self.query = query
        self.seed = seed
        self.parts: Parts = parts if parts is not None else match_parts(registration, query)
        self._indices: dict[int, tuple[np.ndarray, SurfaceIndex]] = {}

    def closest(self, q_part: int, points: np.ndarray) -> tuple:
        """(face (N,), barycentrics (N, 3), distance (N,)) of the closest points to
        ``points`` of query part ``q_part`` on the deformed example: on its matched part,
        else on its parts matched to none (else on all of it)."""
        parts = self.parts
        key = parts.pairs.get(q_part, -1)
        if key not in self._indices:
            if key >= 0:
                subset = np.flatnonzero(parts.example == key)
            else:
                matched = set(parts.pairs.values())
                subset = np.flatnonzero(~np.isin(parts.example, list(matched)))
                if not subset.size:
                    subset = np.arange(len(self.registration.faces))
            index = SurfaceIndex(self.registration.deformed, self.registration.faces[subset],
                                 self.seed)  # fmt: skip
            self._indices[key] = (subset, index)
        subset, index = self._indices[key]
        face, bary, distance = index.closest(points)
        return subset[face], bary, distance

    @cached_property
    def guides(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(welded vertices, each vertex's welded index, welded normals, curvature) of the
        rigid fit."""
        welded, welded_faces, index = weld(self.registration.vertices, self.registration.faces)
        normals = _vertex_normals(welded, welded_faces)
        curvature = vertex_curvature(welded, welded_faces, normals)
        return welded, index, normals, curvature


def resample(
    example,
    registration: Registration,
    query,
    size: int,
    seed: int = 0,
    *,
    surface: RegisteredSurface | None = None,
    colour: bool = True,
) -> Resampled:
    """An example's texture and surface guides in the query's atlas at ``size``.

    Parameters
    ----------
    example : trimesh.Trimesh
        The example, with UVs and a texture.
    registration : Registration
        Its registration to the query (:func:`register_rigid`, :func:`deform`).
    query : trimesh.Trimesh or MeshSurface
        With per-vertex UVs (a :class:`MeshSurface` rasterizes its atlas once per size,
        for every example).
    size : int
    seed : int
    surface : RegisteredSurface, optional
        What this example's resampling reads at every size (made here when not given).
    colour : bool
        Sample the texture too (False: the guides only; ``colour`` is None).

    Returns
    -------
    Resampled
    """
    query = MeshSurface.of(query)
    if surface is None:
        surface = RegisteredSurface(registration, query, seed)
    centre, radius, (texel, q_face, points) = query.atlas_points(size)
    faces = registration.faces
    texel_part = surface.parts.query[q_face]
    face = np.zeros(len(points), dtype=np.int64)
    bary = np.zeros((len(points), 3))
    distance = np.zeros(len(points))
    for q_part in np.unique(texel_part):
        here = texel_part == q_part
        face[here], bary[here], distance[here] = surface.closest(int(q_part), points[here])
    own_bary = bary[:, ::-1] if registration.mirrored else bary
    bands = 10 if colour else 7
    # The guides: the same surface point on the rigidly registered example.
    welded, index, normals, curvature = surface.guides
    corners = index[faces[face]]
    position = np.einsum("nk,nkc->nc", bary, welded[corners])
    normal = np.einsum("nk,nkc->nc", bary, normals[corners])
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-12)
    texel_curvature = np.einsum("nk,nk->n", bary, curvature[corners]) * radius
    spread = float(np.percentile(np.abs(texel_curvature), 95)) or 1.0
    texel_curvature = spread * np.tanh(texel_curvature / spread)
    used = np.zeros((size, size), dtype=bool)
    used.flat[texel] = True
    distance_map = np.zeros((size, size), dtype=np.float32)
    distance_map.flat[texel] = distance / radius
    # Every used texel is the example's: its colour and guides are its own closest point's,
    # however far (a fin's tip the example's fin lacks is still of its matched part, the
    # fin's rim); the guides' position, the example's point against the query's, tells the
    # synthesis how well the example fits there. Padding outside the charts only: the
    # nearest texel in the atlas is often another chart's (#46: with the texels farther than
    # 0.08 RMS radii padded too, tan blocks of the body on the generated fish's fins, and
    # 1822 texels of fish_008 off every chosen example where now 0). Each padding texel is
    # its nearest used texel's, band by band: the guides the same with or without colour.
    stack = np.zeros((size * size, bands), dtype=np.float32)
    stack[texel, :3] = (position - centre) / radius
    stack[texel, 3:6] = normal
    stack[texel, 6] = texel_curvature
    if colour:  # the example's own faces (its own winding, its own UVs)
        stack[texel, 7:10] = surface_colours(example, face, own_bary)
    stack = fill_background(stack.reshape(size, size, bands), used)
    maps = SurfaceMaps(
        mask=used,
        position=stack[..., :3].copy(),
        normal=stack[..., 3:6].copy(),
        curvature=stack[..., 6].copy(),
    )
    where = (np.array(texel), face.astype(np.int32), own_bary.astype(np.float32))
    made = np.clip(stack[..., 7:10], 0.0, 1.0) if colour else None
    return Resampled(made, maps, distance_map, where)


@dataclass
class RegisteredExample(UVExample):
    """A mesh example in another layout, resampled into the query's atlas.

    ``texture`` is its colour in the query's layout at the output size (uint8), and
    :meth:`maps` its guides there at any size (made on first use), so that
    :func:`imagemap.mesh.uvspace.colorize_uv` takes it as an example in the layout.
    """

    example_mesh: object = None
    query: object = None
    registration: Registration | None = None
    seed: int = 0
    correspondence: tuple | None = None  # Resampled.correspondence at the output size

    def maps(self, size: int) -> SurfaceMaps:
        """Its guides in the query's atlas at ``size`` (resampled on first use)."""
        if self.registration is None:
            raise ValueError(f"{self.name}: a registered example without its registration")
        if size not in self._maps:
            self._maps[size] = resample(
                self.example_mesh, self.registration, self.query, size, self.seed, colour=False
            ).maps
        return self._maps[size]


def registered_examples(
    query,
    examples: dict[str, object],
    *,
    m: int,
    texture_size: int,
    mirror: bool = False,
    names: list[str] | None = None,
    seed: int = 0,
    guide_size: int | None = None,
) -> tuple[list[RegisteredExample], dict[str, float]]:
    """The ``m`` mesh examples nearest the query in shape, registered and resampled into
    its atlas.

    Parameters
    ----------
    query : trimesh.Trimesh
        With per-vertex UVs.
    examples : dict
        Name -> textured trimesh (UVs and a texture).
    m : int
        How many to keep (by registration residual), unless ``names`` are given.
    texture_size : int
        The output texture's size: the examples' colours are resampled at it.
    mirror : bool
        Mirrored registrations are candidates (:func:`register_rigid`).
    names : list of str, optional
        The examples to use (all registered; no choice).
    seed : int
    guide_size : int, optional
        Each example's guides are made at this size too (the engine's working size), with
        its texture, on the same closest-point indices (:meth:`RegisteredExample.maps`
        makes those of any other size when asked).

    Returns
    -------
    (list of RegisteredExample, nearest first; dict name -> residual of every example)
    """
    start = time.perf_counter()
    # What every example reads of the query (its samples, frame, parts, atlas points at
    # each size) and each example's samples and frame (its fit and its refinement): made
    # once, and let go on return (nothing here is kept through the synthesis).
    surface = MeshSurface(query)
    _ = surface.frame  # a query of no surface: an InputError before any example's work
    surfaces = {name: MeshSurface(mesh) for name, mesh in examples.items()}
    fits = {}
    for name in examples:
        try:
            fits[name] = register_rigid(surfaces[name], surface, mirror, seed, refine=False)
        except InputError as error:  # a degenerate example: named
            raise InputError(f"mesh example {name}: {error}") from error
    residuals = {name: fit.residual for name, fit in fits.items()}
    if names:
        chosen = list(names)
    else:
        chosen = sorted(residuals, key=lambda n: residuals[n])[: max(1, m)]
    deformed = {}
    for name in chosen:
        # Chosen by the ICP fit's residual; only the chosen are refined (its cost).
        fits[name] = refine_rigid(fits[name], surfaces[name], surface, seed)
        parts = match_parts(fits[name], surface)  # the deformation keeps the rigid fit's
        deformed[name] = deform(fits[name], surface, seed, parts), parts
    surface.release_indices()  # the query's (the deformations'), before the resampling's
    made = []
    for name in chosen:
        fit, parts = deformed.pop(name)
        on_query = RegisteredSurface(fit, surface, seed, parts)  # for both sizes
        resampled = resample(examples[name], fit, surface, texture_size, seed, surface=on_query)
        if resampled.colour is None:
            raise RuntimeError("resample made no colour")
        texture = np.round(resampled.colour * 255.0).astype(np.uint8)
        correspondence = resampled.correspondence
        del resampled  # (its guides at the output size: not used)
        example = RegisteredExample(
            name,
            query,
            texture,
            example_mesh=examples[name],
            query=query,
            registration=fit,
            seed=seed,
            correspondence=correspondence,
        )
        if guide_size is not None:
            example._maps[guide_size] = resample(
                examples[name], fit, surface, guide_size, seed, surface=on_query, colour=False
            ).maps
        made.append(example)
    log.info(
        "registered %d mesh examples in %.1f s (residual in RMS radii: %s); kept %s%s",
        len(examples),
        time.perf_counter() - start,
        ", ".join(f"{n} {r:.3f}" for n, r in sorted(residuals.items(), key=lambda x: x[1])),
        ", ".join(chosen),
        " (mirrored: " + ", ".join(n for n in chosen if fits[n].mirrored) + ")"
        if any(fits[n].mirrored for n in chosen)
        else "",
    )
    return made, residuals
