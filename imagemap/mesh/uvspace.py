"""Synthesis in a shared UV atlas: no view, nothing hidden, nothing mirrored.

One module for one job: the UV-space front end (surface guides, layout test, selection,
its stage tuple and entry point).

When the query mesh and the example meshes share one UV layout (a registered
template, as scanned faces are), texel (u, v) is the same point of the object on
every mesh, and the examples' own textures are already aligned with the query's.
The synthesis then runs in the atlas itself: one :class:`~imagemap.core.mapping.Mapping`
per mesh whose guide bands are surface properties at every texel, and whose
appearance bands (for the examples) are their own textures.

Guide bands (:func:`surface_maps`), per texel of the atlas' used texels:

- **position**: the 3-D surface point, relative to the object (minus the mean over the
  used texels, over their RMS radius), so heads of other sizes and placements compare;
- **normal**: the unit surface normal (three bands);
- **curvature**: the mean curvature of the surface (the umbrella operator's normal
  component over the squared edge length, times the RMS radius: scale-free, positive
  where convex).

Outside the charts (the padding) every band is continued from the nearest used texel
(:func:`surface_maps`). The synthesis (:func:`colorize_uv`) then reads the padding its
windows reach on the surface itself (:mod:`imagemap.mesh.padding`): each such texel takes
the guides, and each example's appearance, at the surface point that continues its
nearest chart across the border, in the chart on the other side of the seam; so a
window at a chart's border sees the surface beyond the seam, not the border repeated.
The mask is the used texels.

The engine (:func:`imagemap.core.engine.synthesize`) runs at a working size of at
most :data:`WORKING_SIZE` texels; the depth front end's finish then copies each texel
from the example texel its windows agree on and places and blends the seams
(:func:`imagemap.core.seams.place_seams`, :func:`~imagemap.core.poisson.seamless_copy`).
The texture is made at the output size by copying every output texel from its
example's full-resolution texture through the working source map (the position
interpolated between the working texels that continue one copy,
:func:`imagemap.core.finecopy.fine_positions`), plus the blend's smooth correction
interpolated: so the result is as crisp as the examples' textures.

Examples
--------
>>> import trimesh
>>> grid = trimesh.creation.box(extents=(2.0, 1.0, 0.5)).subdivide()
>>> uv = np.c_[grid.vertices[:, 0] / 4 + 0.5, grid.vertices[:, 1] / 2 + 0.5]
>>> maps = surface_maps(grid.vertices, grid.faces, uv, 32)
>>> maps.mask.shape, maps.guides().shape[2]
((32, 32), 7)
"""

from __future__ import annotations

import hashlib
import logging
import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from scipy import ndimage, sparse

from imagemap.cache import cache_dir, source_digest
from imagemap.core.blend import copy_through, fill_background
from imagemap.core.engine import ReleasableLevels, synthesize
from imagemap.core.finecopy import fine_positions
from imagemap.core.mapping import Mapping
from imagemap.core.poisson import seamless_copy
from imagemap.core.pyramid import gaussian_pyramid, laplacian_pyramid, mask_pyramid
from imagemap.core.stages import Stage, run_pipeline
from imagemap.depth.finish import (
    BLEND,
    COLLAPSE,
    COPY,
    OUTSIDE,
    RGB,
    SEAMS,
    Picture,
    SynthesisState,
)
from imagemap.depth.guides import sized_config, to_ycbcr
from imagemap.depth.pipeline import ColorizeResult, engine_params
from imagemap.errors import InputError
from imagemap.io import read_npz, write_npz
from imagemap.mesh.padding import SurfacePadding, engine_reach, surface_padding, weld
from imagemap.scene.bake import covered_texels, rasterize_uv
from imagemap.scene.views import sample_pixels

__all__ = [
    "LAYOUT_TEST_SIZE",
    "WORKING_SIZE",
    "SurfaceMaps",
    "UVExample",
    "colorize_uv",
    "layout_agreement",
    "same_texel_source",
    "same_uv_layout",
    "select_uv_examples",
    "surface_maps",
]

log = logging.getLogger("imagemap")

#: The engine runs at most at this atlas size; larger textures are copied through its
#: source map (see the module notes). The heads' layout uses 62k texels of 256^2, about
#: the pixels of three 200x150 views' objects; at 512^2 the engine took 5x as long (115
#: against 20 s on a loaded machine) for no better UV error (ffhq_teaser1: 10.95 against
#: 10.76 of 255).
WORKING_SIZE = 256
#: UV coordinates are the same when they differ by less than this (texture units):
#: a tenth of a texel of a 1024^2 texture.
UV_TOLERANCE = 1e-4
#: Atlas size of the topology-free layout test (:func:`layout_agreement`).
LAYOUT_TEST_SIZE = 64
#: Two meshes share a layout when their used texels overlap at least this much
#: (intersection over union; the FLAME head and the HiFi3D++ heads of FFHQ-UV, one
#: layout: 0.967; generated fish in their own xatlas atlases: 0.46-0.64) ...
LAYOUT_MIN_IOU = 0.85
#: ... and the median distance between their normalised surface points at the common
#: texels is below this, in RMS radii (FLAME against HiFi3D++: 0.08; a HiFi3D++ head
#: against its layout mirrored, IoU 1.0: 0.78; fish: 0.55-0.79).
LAYOUT_MAX_DISTANCE = 0.3
#: The shared finish (:mod:`imagemap.depth.finish`) that the uv-space synthesis runs after
#: its own ``select``, ``bands`` and ``synthesize``: it works on the source map and the
#: colours only. Not run: the depth front end's stages that read depth (the query's depth
#: scale and the query-in-database check, registration, and the completion of small
#: features, which registers depth relief).
FINISH_STAGES = (COLLAPSE, COPY, SEAMS, OUTSIDE, BLEND, RGB)
#: Guide weights (per band standard deviation): the surface point places a texel on the
#: object; the normal and curvature say what the surface does there.
POSITION_WEIGHT = 1.0
NORMAL_WEIGHT = 1.0
CURVATURE_WEIGHT = 0.5


@dataclass
class SurfaceMaps:
    """Surface properties at every texel of a square atlas.

    Attributes
    ----------
    mask : (T, T) bool
        The used texels (covered by some UV triangle).
    position : (T, T, 3) float32
        The normalised surface point (see the module notes); padded outside ``mask`` from
        the nearest used texel (the synthesis pads on the surface, :mod:`~imagemap.mesh.padding`).
    normal : (T, T, 3) float32
        Unit normals; padded.
    curvature : (T, T) float32
        Scale-free mean curvature; padded.
    raster : (texel (N,), face (N,), barycentrics (N, 3)) or None
        The atlas' rasterization these maps were made from
        (:func:`imagemap.scene.bake.rasterize_uv` at ``size``): each used texel's face
        and barycentrics, kept so that the surface padding of the same atlas
        (:func:`imagemap.mesh.padding.surface_padding`) does not rasterize it again;
        None for maps made otherwise (resampled examples).
    """

    mask: np.ndarray
    position: np.ndarray
    normal: np.ndarray
    curvature: np.ndarray
    raster: tuple[np.ndarray, np.ndarray, np.ndarray] | None = field(
        default=None, repr=False, compare=False
    )

    @property
    def size(self) -> int:
        return self.mask.shape[0]

    def guides(
        self,
        position_weight: float = POSITION_WEIGHT,
        normal_weight: float = NORMAL_WEIGHT,
        curvature_weight: float = CURVATURE_WEIGHT,
    ) -> np.ndarray:
        """The guide bands (T, T, B): position, normal, curvature (bands weighted 0 left out)."""
        bands = []
        if position_weight:
            bands.append(self.position)
        if normal_weight:
            bands.append(self.normal)
        if curvature_weight:
            bands.append(self.curvature[..., None])
        if not bands:
            raise InputError("uv-space synthesis: every guide weight is 0")
        return np.concatenate(bands, axis=2).astype(np.float32)


def guide_weights(
    position_weight: float = POSITION_WEIGHT,
    normal_weight: float = NORMAL_WEIGHT,
    curvature_weight: float = CURVATURE_WEIGHT,
) -> tuple[float, ...]:
    """One weight per band of :meth:`SurfaceMaps.guides`.

    Examples
    --------
    >>> guide_weights(1.0, 0.0, 0.5)  # no normal bands
    (1.0, 1.0, 1.0, 0.5)
    """
    return tuple(
        [position_weight] * 3 * bool(position_weight)
        + [normal_weight] * 3 * bool(normal_weight)
        + [curvature_weight] * bool(curvature_weight)
    )


def vertex_curvature(vertices: np.ndarray, faces: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Mean curvature per vertex (1 / length): the umbrella operator along the normal.

    ``-(mean of the neighbours - vertex) . normal`` over the squared mean edge length:
    positive where the surface is convex; a vertex without neighbours gets 0.

    Examples
    --------
    >>> import trimesh
    >>> sphere = trimesh.creation.icosphere(subdivisions=3, radius=2.0)
    >>> k = vertex_curvature(sphere.vertices, sphere.faces, sphere.vertex_normals)
    >>> bool(np.all(k > 0)), round(float(np.median(k) * 2.0), 1)
    (True, 0.5)
    """
    n = len(vertices)
    edges = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    keys = np.unique(edges[:, 0] * n + edges[:, 1])  # each undirected edge once
    edges = np.stack([keys // n, keys % n], axis=1)
    i, j = np.r_[edges[:, 0], edges[:, 1]], np.r_[edges[:, 1], edges[:, 0]]
    lengths = np.linalg.norm(vertices[i] - vertices[j], axis=1)
    adjacency = sparse.csr_matrix((np.ones(len(i)), (i, j)), shape=(n, n))
    degree = np.asarray(adjacency.sum(axis=1)).ravel()
    safe = np.maximum(degree, 1.0)
    mean_neighbour = (adjacency @ vertices) / safe[:, None]
    mean_length = (
        np.asarray(sparse.csr_matrix((lengths, (i, j)), shape=(n, n)).sum(axis=1)).ravel() / safe
    )
    along = -np.einsum("nc,nc->n", mean_neighbour - vertices, normals)
    curvature = along / np.maximum(mean_length, 1e-12) ** 2
    return np.where(degree > 0, curvature, 0.0)


def _vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Area-weighted vertex normals (unit; 0 for a vertex of no face)."""
    corners = vertices[faces]
    face_normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    normals = np.zeros_like(vertices)
    for k in range(3):
        np.add.at(normals, faces[:, k], face_normals)
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    return normals / np.maximum(length, 1e-12)


def surface_maps(vertices: np.ndarray, faces: np.ndarray, uv: np.ndarray, size: int) -> SurfaceMaps:
    """The surface's position, normal and curvature at every texel of a ``size``^2 atlas.

    Parameters
    ----------
    vertices : (V, 3) array
    faces : (F, 3) int array
    uv : (V, 2) array
        Per-vertex texture coordinates (GL style: v up). Triangles outside [0, 1]^2
        cover no texel.
    size : int
        Width and height of the atlas.

    Returns
    -------
    SurfaceMaps

    Raises
    ------
    InputError
        When the UVs cover no texel.
    """

    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    texel, face, bary = rasterize_uv(np.asarray(uv, dtype=np.float64), faces, size)
    if texel.size == 0:
        raise InputError("the mesh's UV layout covers no texel")
    welded, welded_faces, _ = weld(vertices, faces)
    normals = _vertex_normals(welded, welded_faces)
    curvature = vertex_curvature(welded, welded_faces, normals)
    corners = welded_faces[face]
    position = np.einsum("nk,nkc->nc", bary, welded[corners])
    normal = np.einsum("nk,nkc->nc", bary, normals[corners])
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-12)
    centre = position.mean(axis=0)
    radius = float(np.sqrt(np.mean(np.sum((position - centre) ** 2, axis=1))))
    radius = radius if radius > 0 else 1.0
    # A heavy-tailed band (creases, the rims of holes) would set its own standard
    # deviation: clipped at a robust spread so that the face's own relief counts.
    texel_curvature = np.einsum("nk,nk->n", bary, curvature[corners]) * radius
    spread = float(np.percentile(np.abs(texel_curvature), 95)) or 1.0
    texel_curvature = spread * np.tanh(texel_curvature / spread)
    mask = np.zeros((size, size), dtype=bool)
    mask.flat[texel] = True
    stack = np.zeros((size * size, 7), dtype=np.float32)
    stack[texel, :3] = (position - centre) / radius
    stack[texel, 3:6] = normal
    stack[texel, 6] = texel_curvature
    stack = fill_background(stack.reshape(size, size, 7), mask)
    return SurfaceMaps(
        mask=mask,
        position=stack[..., :3].copy(),
        normal=stack[..., 3:6].copy(),
        curvature=stack[..., 6].copy(),
        raster=(texel, face, bary),
    )


def mesh_uv_arrays(mesh) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(vertices, faces, per-vertex UVs) of a textured trimesh, or InputError without UVs.

    Examples
    --------
    >>> import trimesh
    >>> mesh_uv_arrays(trimesh.creation.box())
    Traceback (most recent call last):
    ...
    imagemap.errors.InputError: the mesh has no per-vertex UV coordinates
    """
    uv = getattr(mesh.visual, "uv", None)
    if uv is None or len(uv) != len(mesh.vertices):
        raise InputError("the mesh has no per-vertex UV coordinates")
    return (
        np.asarray(mesh.vertices, dtype=np.float64),
        np.asarray(mesh.faces, dtype=np.int64),
        np.asarray(uv, dtype=np.float64),
    )


def same_uv_layout(first, second, tolerance: float = UV_TOLERANCE) -> bool:
    """Whether two meshes have the same UV layout exactly: the same UV faces and UVs.

    The same number of UV vertices and faces, the same faces, and UV coordinates
    within ``tolerance``. Meshes of one registered template pass; meshes of other
    topologies in one layout need :func:`layout_agreement`.

    Examples
    --------
    >>> import trimesh
    >>> a = trimesh.creation.box(); uv = a.vertices[:, :2] / 2 + 0.5
    >>> a.visual = trimesh.visual.TextureVisuals(uv=uv)
    >>> b = a.copy(); b.vertices = b.vertices * 2.0  # another shape, the same layout
    >>> same_uv_layout(a, b)
    True
    """
    uv_a = getattr(first.visual, "uv", None)
    uv_b = getattr(second.visual, "uv", None)
    if uv_a is None or uv_b is None or len(uv_a) != len(uv_b):
        return False
    if first.faces.shape != second.faces.shape or not np.array_equal(first.faces, second.faces):
        return False
    return bool(np.allclose(uv_a, uv_b, rtol=0.0, atol=tolerance))


def layout_agreement(first: SurfaceMaps, second: SurfaceMaps) -> tuple[float, float]:
    """(IoU of the used texels, median distance of the surface points there) of two atlases.

    Topology-free: two meshes in one layout cover nearly the same texels, and the same
    texel is nearly the same normalised point of both objects. A layout that only
    overlaps another (a mirrored one: the HiFi3D++ layout covers 95 % of the atlas)
    puts other points of the object at the same texels.

    Examples
    --------
    >>> import trimesh
    >>> sheet = trimesh.creation.box(extents=(2.0, 1.0, 0.2)).subdivide().subdivide()
    >>> uv = sheet.vertices[:, :2] / [2.0, 1.0] + 0.5
    >>> maps = surface_maps(sheet.vertices, sheet.faces, uv, 32)
    >>> mirrored = surface_maps(sheet.vertices, sheet.faces, uv * [-1, 1] + [1, 0], 32)
    >>> [round(v, 2) for v in layout_agreement(maps, maps)]
    [1.0, 0.0]
    >>> iou, distance = layout_agreement(maps, mirrored)  # the same texels, other points
    >>> round(iou, 2), distance > 0.5
    (1.0, True)
    """
    if first.size != second.size:
        raise ValueError("atlases of different sizes")
    both = first.mask & second.mask
    union = first.mask | second.mask
    iou = float(both.sum() / max(union.sum(), 1))
    if not both.any():
        return iou, float("inf")
    distance = np.linalg.norm(first.position[both] - second.position[both], axis=1)
    return iou, float(np.median(distance))


def shares_layout(query_mesh, example_mesh, query_maps: SurfaceMaps | None = None) -> bool:
    """Whether ``example_mesh`` is in ``query_mesh``'s UV layout (exactly, or by
    :func:`layout_agreement` within :data:`LAYOUT_MIN_IOU` and
    :data:`LAYOUT_MAX_DISTANCE`).

    Examples
    --------
    >>> import trimesh
    >>> sheet = trimesh.creation.box(extents=(2.0, 1.0, 0.2)).subdivide()
    >>> sheet.visual = trimesh.visual.TextureVisuals(uv=sheet.vertices[:, :2] / [2, 1] + 0.5)
    >>> finer = sheet.subdivide()  # another topology, the same layout
    >>> same_uv_layout(sheet, finer), shares_layout(sheet, finer)
    (False, True)
    """
    if same_uv_layout(query_mesh, example_mesh):
        return True
    try:
        if query_maps is None:
            query_maps = surface_maps(*mesh_uv_arrays(query_mesh), LAYOUT_TEST_SIZE)
        example_maps = surface_maps(*mesh_uv_arrays(example_mesh), LAYOUT_TEST_SIZE)
    except InputError:
        return False
    iou, distance = layout_agreement(query_maps, example_maps)
    return iou >= LAYOUT_MIN_IOU and distance <= LAYOUT_MAX_DISTANCE


@dataclass
class UVExample:
    """An example for the UV-space synthesis: a name, its mesh (with UVs) and texture."""

    name: str
    mesh: object
    texture: np.ndarray  # (H, W, 3) uint8, or float in [0, 1]
    _maps: dict = field(default_factory=dict, repr=False)

    def maps(self, size: int) -> SurfaceMaps:
        """Its :class:`SurfaceMaps` at ``size`` (made once per size)."""
        if size not in self._maps:
            self._maps[size] = surface_maps(*mesh_uv_arrays(self.mesh), size)
        return self._maps[size]


def resize_texture(texture: np.ndarray, size: int) -> np.ndarray:
    """A texture resampled to ``size`` x ``size`` (area-averaged when shrinking).

    Examples
    --------
    >>> resize_texture(np.ones((8, 8, 3), np.float32), 4).shape
    (4, 4, 3)
    """
    from skimage.transform import (
        resize,
    )  # deferred: start-up: skimage.transform (0.4 s) only for a resized texture

    texture = _unit(np.asarray(texture)[..., :3])
    if texture.shape[:2] == (size, size):
        return texture
    shrinking = size < max(texture.shape[:2])
    out = resize(texture, (size, size), order=1, anti_aliasing=shrinking, preserve_range=True)
    return np.clip(out, 0.0, 1.0).astype(np.float32)


def select_uv_examples(query: SurfaceMaps, examples: list[SurfaceMaps], m: int) -> list[int]:
    """Indices of the ``m`` examples whose normalised surface is nearest the query's.

    The distance is the mean squared difference of the surface points over the texels
    both use (the UV layout is the correspondence: no alignment needed), plus one for
    the share of the query's used texels an example leaves uncovered.

    Examples
    --------
    >>> mask = np.ones((4, 4), bool); flat = np.zeros((4, 4)); up = np.zeros((4, 4, 3))
    >>> def maps(z):
    ...     return SurfaceMaps(mask, np.dstack([flat, flat, flat + z]), up, flat)
    >>> select_uv_examples(maps(0.0), [maps(0.5), maps(0.1), maps(-0.3)], 2)
    [1, 2]
    """
    distances = []
    for example in examples:
        both = query.mask & example.mask
        if not both.any():
            distances.append(np.inf)
            continue
        squared = np.sum((query.position[both] - example.position[both]) ** 2, axis=1)
        uncovered = 1.0 - both.sum() / query.mask.sum()
        distances.append(float(squared.mean()) + uncovered)
    order = np.argsort(distances, kind="stable")
    return [int(i) for i in order[:m]]


def _uv_mappings(
    guides: np.ndarray, mask: np.ndarray, levels: int, appearance=None, kind="gaussian"
):
    """A pyramid (finest first) of Mappings of guide bands (and appearance) over a mask."""

    masks = mask_pyramid(mask, levels)
    guide_levels = gaussian_pyramid(guides, levels)
    appearance_levels: Sequence[np.ndarray | None]
    if appearance is None:
        appearance_levels = [None] * levels
    elif kind == "laplacian":
        appearance_levels = laplacian_pyramid(appearance, levels)
    else:
        appearance_levels = gaussian_pyramid(appearance, levels)
    return [
        Mapping(guide=g, appearance=a, mask=m if m.any() else None)
        for g, a, m in zip(guide_levels, appearance_levels, masks, strict=True)
    ]


#: Rows of the output texture made at once (bounds the temporaries of the final copy).
_BLOCK_ROWS = 128


def _unit(values: np.ndarray) -> np.ndarray:
    """Texture values as float32 in [0, 1] (uint8 divided by 255)."""
    if values.dtype == np.uint8:
        return values.astype(np.float32) / 255.0
    return values.astype(np.float32)


def fine_texture(
    textures: list[np.ndarray],
    source: np.ndarray,
    correction: np.ndarray,
    size: int,
    used: Sequence[np.ndarray | None] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """The texture at ``size`` copied through a coarser source map from full-size textures.

    Each output texel copies the texel of its example's own texture (any size) nearest to
    its position in the copy (:func:`imagemap.core.finecopy.fine_positions`: interpolated
    between the working texels' sources that continue its working texel's copy, so a copy
    that drifts by one working texel steps one texel at a time, and two patches from
    far-apart places are not mixed), plus ``correction`` (W, W, C) interpolated between the
    working texels' centres. Detail is then the examples' own, at their resolution.

    Parameters
    ----------
    textures : list of (H_k, W_k, C) arrays
        Each example's full texture (uint8 or float in [0, 1]).
    source : (W, W, 3) int array
        Example, y, x in the working atlas (example < 0: none; taken as example 0).
    correction : (W, W, C) array
        The finish's smooth correction per working texel, added interpolated.
    size : int
    used : list of (H_k, W_k) bool arrays or None, optional
        Each example's used texels. A texel whose interpolated position reads one that is
        not used, where its own working texel's copy (the block's position) reads one
        that is, takes the latter: a copy drifting across a chart's narrow gap (a mouth's
        slit between the lips' charts) never reads the gap's padding, which is the
        surface beyond the seam, not this part of the copy.

    Returns
    -------
    (texture (size, size, C) float32 clipped to [0, 1], source (size, size, 3) int32 into
    the examples' own textures)

    Examples
    --------
    A 4 x 4 atlas copies its example where it lies, but working texel (0, 1) copies the
    working texel (3, 3), far away: at 8 x 8 its four texels copy the four under that
    one, not mixed with their neighbours' positions:

    >>> texture = np.arange(64, dtype=np.float32).reshape(8, 8, 1) / 64
    >>> src = np.zeros((4, 4, 3), np.int32); src[..., 1:] = np.moveaxis(np.indices((4, 4)), 0, -1)
    >>> src[0, 1] = (0, 3, 3)
    >>> image, fine = fine_texture([texture], src, np.zeros((4, 4, 1), np.float32), 8)
    >>> fine[0:2, 2:4, 1:].tolist()
    [[[6, 6], [6, 7]], [[7, 6], [7, 7]]]
    >>> (image[0:2, 2:4, 0] * 64).tolist()
    [[54.0, 55.0], [62.0, 63.0]]
    >>> bool(np.array_equal(fine[4:, :, 1:], np.moveaxis(np.indices((4, 8)), 0, -1) + (4, 0)))
    True
    """
    working = source.shape[0]
    heights = np.array([t.shape[0] for t in textures], dtype=np.float64)
    widths = np.array([t.shape[1] for t in textures], dtype=np.float64)
    channels = correction.shape[2]
    correction = np.asarray(correction, dtype=np.float32)
    centres = (np.arange(size) + 0.5) * working / size - 0.5  # in working texels
    image = np.empty((size, size, channels), dtype=np.float32)
    fine = np.empty((size, size, 3), dtype=np.int32)
    for y0 in range(0, size, _BLOCK_ROWS):
        y1 = min(y0 + _BLOCK_ROWS, size)
        at = fine_positions(source, size / working, (size, size), (y0, y1))
        index = np.clip(at.index, 0, len(textures) - 1)
        # The example's texel whose centre is nearest the position, (p + 0.5) * s - 0.5.
        sy = _texel_at(at.y + 0.5, heights[index], working)
        sx = _texel_at(at.x + 0.5, widths[index], working)
        if used is not None:
            _keep_to_used(used, source, at, index, sy, sx, heights, widths)
        # The finish's smooth correction, between the working texels' centres.
        grid_y, grid_x = np.meshgrid(centres[y0:y1], centres, indexing="ij")
        block = sample_pixels(correction, grid_x.ravel(), grid_y.ravel())
        block = block.reshape(y1 - y0, size, channels)
        for k, texture in enumerate(textures):
            here = index == k
            block[here] += _unit(texture[sy[here], sx[here]][..., :channels])
        image[y0:y1] = np.clip(block, 0.0, 1.0)
        fine[y0:y1] = np.stack([index, sy, sx], axis=-1)
    return image, fine


def _texel_at(edge: np.ndarray, extent: np.ndarray, working: int) -> np.ndarray:
    """The texel of an example ``extent`` texels across that holds the point ``edge``
    working texels from its edge (int32, clipped to the example)."""
    return np.clip(np.floor(edge * extent / working), 0, extent - 1).astype(np.int32)


def _keep_to_used(used, source, at, index, sy, sx, heights, widths):
    """``sy``, ``sx`` (one band of :func:`fine_texture`'s rows, ``at`` its
    :class:`~imagemap.core.finecopy.FinePositions`) moved, in place, to the own working
    texel's block position where they read an unused texel of their example and that
    position reads a used one."""
    working = source.shape[0]
    # The own working texel's source plus the output texel's place within that texel.
    cy, cx = at.cell_y, at.cell_x
    own_y = _texel_at(source[cy][:, cx, 1] + at.within_y[:, None], heights[index], working)
    own_x = _texel_at(source[cy][:, cx, 2] + at.within_x[None, :], widths[index], working)
    for k, mask in enumerate(used):
        if mask is None:
            continue
        here = np.flatnonzero(index.ravel() == k)
        gap = ~mask[sy.flat[here], sx.flat[here]] & mask[own_y.flat[here], own_x.flat[here]]
        moved = here[gap]
        sy.flat[moved], sx.flat[moved] = own_y.flat[moved], own_x.flat[moved]


#: The code that pads (this module and :mod:`imagemap.mesh.padding`): its source is part of
#: a padded texture's cache key, so an edit to either makes the paddings anew.
PADDING_SOURCES = ("mesh/uvspace.py", "mesh/padding.py")


def _padded_cache_dir() -> Path:
    """Where the examples' padded textures are cached: ``padded/`` in the library's cache
    (``$IMAGEMAP_CACHE``, default ``~/.cache/imagemap``; the examples' renders are in
    ``meshes/`` there)."""
    return cache_dir() / "padded"


def _padded_key(arrays: Sequence[np.ndarray], size: int, reach: int) -> str:
    """The cache key of an example's padded texture: a digest of what the padding reads
    (its vertices, faces, UVs and texture: their dtype, shape and bytes), the size, the
    reach and the code that pads (:data:`PADDING_SOURCES`' source: an edit to either makes
    the paddings anew, with no version number to remember)."""
    digest = hashlib.sha256(source_digest(PADDING_SOURCES).encode())
    for array in arrays:
        array = np.ascontiguousarray(array)
        digest.update(f"{array.dtype.str}{array.shape}|".encode())
        digest.update(array.data)  # C-contiguous: its bytes
    digest.update(f"{size}|{reach}".encode())
    return digest.hexdigest()[:24]


def _surface_padded(
    example: UVExample, texture: np.ndarray, working: int
) -> tuple[np.ndarray, np.ndarray | None]:
    """An example's full-size texture (float32) with the padding within one working texel
    of its charts read on its surface (:mod:`imagemap.mesh.padding`), and its used texels
    (bool, its size); a texture that is not square is returned as it is, with None.

    It depends on the example alone (its mesh, texture and the working size), so it is
    cached on disk beside the examples' renders (:func:`_padded_cache_dir`), keyed by a
    digest of those (:func:`_padded_key`): the texels it changed and their values, so a
    cached read gives the same bytes. A damaged entry is made anew; a cache that cannot
    be written only costs time.
    """
    size = texture.shape[0]
    if texture.shape[1] != size:
        return texture, None
    vertices, faces, uv = mesh_uv_arrays(example.mesh)
    reach = int(np.ceil(size / working)) + 1
    plain = _unit(texture)
    flat = plain.reshape(size * size, -1)
    cached = (
        _padded_cache_dir()
        / f"{example.name}-{_padded_key((vertices, faces, uv, texture), size, reach)}.npz"
    )
    if cached.is_file():
        try:
            arrays = read_npz(cached, what="cached padded texture")
            texel, values = arrays["texel"], arrays["values"]
            used = np.unpackbits(arrays["used"], count=size * size).astype(bool)
            fits = values.dtype == np.float32 and values.shape == (len(texel), flat.shape[1])
            if fits and (texel.size == 0 or 0 <= texel.min() <= texel.max() < len(flat)):
                flat[texel] = values  # plain is this call's own copy (_unit)
                return plain, used.reshape(size, size)
        except (InputError, KeyError, IndexError, ValueError):
            pass  # made anew
    pad = surface_padding(vertices, faces, uv, size, reach)
    out = pad.apply(plain, pad.mask)
    changed = np.flatnonzero(np.any(out.reshape(size * size, -1) != flat, axis=1))
    try:
        write_npz(
            cached,
            texel=changed.astype(np.int64),
            values=out.reshape(size * size, -1)[changed],
            used=np.packbits(pad.mask.ravel()),
        )
    except OSError:
        pass  # a read-only cache only costs time
    return out, pad.mask


def same_texel_source(source: np.ndarray, mask: np.ndarray, examples: int) -> np.ndarray:
    """The source map with every texel copied from the same texel of its example.

    On the registered path every example is resampled into the query's atlas, so texel
    ``t`` of each is (an estimate of) the query's surface point at ``t``, at every used
    texel (:func:`imagemap.mesh.register.resample`): the synthesis chooses only *which*
    example a texel comes from. Copying ``t`` from ``t + offset`` (the engine's match)
    lands, near a chart's border, in another chart or the padding: specks of other charts'
    colours. Here the offset is dropped and the example (the label) kept. Texels outside
    ``mask`` or without a source take the label of the nearest used texel with one.

    Parameters
    ----------
    source : (T, T, 3) int array
        Example, y, x per texel (example < 0: none).
    mask : (T, T) bool
        The query's used texels.
    examples : int
        How many examples there are (a label outside ``0 .. examples - 1`` is none).

    Returns
    -------
    (T, T, 3) int32: example, y, x; y, x the texel's own.

    Examples
    --------
    Two charts (columns 0-1 and 3), every match at texel (1, 2) (padding); texel (1, 0)
    has no source and takes its nearest neighbour's label:

    >>> source = np.zeros((2, 4, 3), np.int32); source[..., 0] = [[0, 1, 0, 1], [-1, 0, 0, 0]]
    >>> source[..., 1:] = [1, 2]
    >>> mask = np.array([[1, 1, 0, 1], [1, 1, 0, 1]], bool)
    >>> out = same_texel_source(source, mask, 2)
    >>> out[mask, 0].tolist(), out[0, 3, 1:].tolist(), out[1, 1, 1:].tolist()
    ([0, 1, 1, 0, 0, 0], [0, 3], [1, 1])
    """
    height, width = mask.shape
    label = source[..., 0].astype(np.int32)
    known = mask & (label >= 0) & (label < examples)
    label = fill_background(label, known) if known.any() else np.zeros_like(label)
    rows, cols = np.indices((height, width), dtype=np.int32)
    return np.stack([label, rows, cols], axis=-1).astype(np.int32)


def _charts_with_seams(source: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Texels (padding: of the nearest chart) whose chart of ``mask`` holds a seam of
    ``source``: two neighbours copied from different examples or not from neighbouring
    texels.

    Examples
    --------
    >>> mask = np.array([[1, 1, 0, 0, 1, 1]], bool)
    >>> source = np.zeros((1, 6, 3), np.int32); source[0, :, 2] = np.arange(6)
    >>> source[0, 5, 0] = 1  # a seam in the right chart
    >>> _charts_with_seams(source, mask).astype(int).tolist()
    [[0, 0, 0, 1, 1, 1]]
    """
    step = np.zeros(mask.shape, dtype=bool)
    across = np.any(source[:, 1:] - source[:, :-1] != (0, 0, 1), axis=-1)
    down = np.any(source[1:] - source[:-1] != (0, 1, 0), axis=-1)
    step[:, 1:] |= across
    step[:, :-1] |= across
    step[1:] |= down
    step[:-1] |= down
    charts, count = ndimage.label(mask)
    charts = fill_background(charts, charts > 0)
    seamed = np.zeros(count + 1, dtype=bool)
    seamed[charts[step & mask]] = True
    return seamed[charts]


def colorize_uv(
    mesh,
    examples: list[UVExample],
    config,
    *,
    size: int,
    names: list[str] | None = None,
    seed: int = 0,
    quiet: bool = True,
    working_size: int = WORKING_SIZE,
    weights: tuple[float, float, float] = (POSITION_WEIGHT, NORMAL_WEIGHT, CURVATURE_WEIGHT),
    same_texel: bool = False,
):
    """Synthesise a texture in the query's UV atlas from examples in the same layout.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        The query, with per-vertex UVs (its own texture, if any, is not read).
    examples : list of UVExample
        The examples, all in the query's layout.
    config : DepthConfig
        The depth front end's configuration (the selection's ``m``, the pyramid, the
        matching and the finish are used; the depth's guide bands are not).
    size : int
        The texture's width and height.
    names : list of str, optional
        The examples to use; default: the ``m`` nearest in surface
        (:func:`select_uv_examples`).
    seed, quiet
        As :func:`imagemap.colorize`.
    working_size : int
        The atlas size the engine runs at (at most ``size``).
    weights : (float, float, float)
        Weights of the position, normal and curvature bands (0 leaves a band out).
    same_texel : bool
        Copy every texel from the same texel of the example the synthesis chose for it
        (:func:`same_texel_source`; the seams are then placed and blended between
        examples only): for examples resampled into the query's atlas (the registered
        path), where an offset can only take another chart's colour.

    Returns
    -------
    ColorizeResult
        ``image`` is the texture (``size`` x ``size``, padded outside the charts),
        ``mask`` the used texels, ``source`` every texel's example, y, x in that
        example's own texture.

    Examples
    --------
    A sheet textured from its own texture gives that texture back:

    >>> import trimesh
    >>> from imagemap.depth.config import resolve_config
    >>> sheet = trimesh.creation.box(extents=(2.0, 1.0, 0.2)).subdivide().subdivide()
    >>> sheet.visual = trimesh.visual.TextureVisuals(uv=sheet.vertices[:, :2] / [2, 1] + 0.5)
    >>> texture = np.random.default_rng(0).random((32, 32, 3)).astype(np.float32)
    >>> result = colorize_uv(sheet, [UVExample("sheet", sheet, texture)],
    ...                      resolve_config("busts"), size=32)
    >>> result.example_names, bool(np.allclose(result.image, texture, atol=1e-6))
    (['sheet'], True)
    """

    working = int(min(working_size, size))
    vertices, faces, uv = mesh_uv_arrays(mesh)
    query = surface_maps(vertices, faces, uv, working)
    by_name = {e.name: e for e in examples}
    if names:
        missing = [n for n in names if n not in by_name]
        if missing:
            raise InputError(
                f"examples: {', '.join(missing)} not in the query's UV layout "
                f"(in it: {', '.join(by_name) or 'none'})"
            )
        chosen = [by_name[n] for n in names]
    else:
        m = min(config.selection.m, len(examples))
        order = select_uv_examples(query, [e.maps(working) for e in examples], m)
        chosen = [examples[i] for i in order]
    textures = [resize_texture(e.texture, working) for e in chosen]
    pictures = [
        Picture(e.name, texture, e.maps(working).mask)
        for e, texture in zip(chosen, textures, strict=True)
    ]
    band_weights = guide_weights(*weights)

    def select(state: SynthesisState, config) -> SynthesisState:
        state.chosen = pictures
        state.changed = ", ".join(e.name for e in pictures)
        return state

    paddings: dict[int, SurfacePadding] = {}

    def padding_of(owner, reach: int, maps: SurfaceMaps) -> SurfacePadding:
        """The surface padding of a mesh's atlas at the working size (once per mesh: the
        registered examples all lie on the query's), on the rasterization its ``maps``
        were made from when they kept it."""
        if id(owner) not in paddings:
            raster = maps.raster if maps.size == working else None
            paddings[id(owner)] = surface_padding(
                *mesh_uv_arrays(owner), working, reach, raster=raster
            )
        return paddings[id(owner)]

    def bands(state: SynthesisState, config) -> SynthesisState:
        levels, kind = config.pyramid.levels, config.matching.appearance_pyramid
        # The padding the windows reach, read on the surface across the seams.
        reach = engine_reach(config.pyramid.patch_sizes)
        pad = padding_of(mesh, reach, query)
        state.query_levels = ReleasableLevels(
            _uv_mappings(pad.apply(query.guides(*weights), query.mask), query.mask, levels)
        )
        exemplar_levels = []
        for e, texture in zip(chosen, textures, strict=True):
            maps = e.maps(working)
            pad = padding_of(e.mesh, reach, maps)
            exemplar_levels.append(
                ReleasableLevels(
                    _uv_mappings(
                        pad.apply(maps.guides(*weights), maps.mask),
                        maps.mask,
                        levels,
                        to_ycbcr(pad.apply(texture, maps.mask)),
                        kind,
                    )
                )
            )
        state.exemplar_levels = exemplar_levels
        placed = ", ".join(str(p.texel.size) for p in paddings.values())
        state.changed = (
            f"{len(chosen)} examples' surface guides and textures; padding within "
            f"{reach} texels read on the surface ({placed} texels)"
        )
        return state

    def engine(state: SynthesisState, config) -> SynthesisState:
        params = replace(
            engine_params(config, state.mask, len(pictures)),
            guide_weights=band_weights,
            guide_padding="edge",
        )
        query_levels, exemplar_levels = state.made("query_levels"), state.made("exemplar_levels")
        state.query_levels = state.exemplar_levels = None
        state.engine = synthesize(query_levels, exemplar_levels, params, seed=state.seed,
                                  quiet=state.quiet)  # fmt: skip
        state.changed = "iterations per level (fine to coarse): " + ", ".join(
            str(len(values)) for values in state.engine.objective
        )
        return state

    def same(state: SynthesisState, config) -> SynthesisState:
        old = state.made("source")
        state.source = same_texel_source(old, query.mask, len(pictures))
        # The colours copied are the examples' own at every texel: the copy stage's refill
        # of the texels outside an example's mask from the nearest inside it (in the atlas:
        # often another chart) would reach the texture through the blend's correction.
        state.exemplars = [to_ycbcr(texture) for texture in textures]
        moved = query.mask & np.any(old[..., 1:] != state.source[..., 1:], axis=-1)
        state.changed = f"{int(moved.sum())} texels copied from their own texel instead"
        return state

    def blend(state: SynthesisState, config) -> SynthesisState:
        # The depth finish's blend with two changes. The charts' outlines are not the
        # object's: every texel (padding too) is copied from its own texel, so across an
        # outline the copy's own step is kept. And the copy is its own reference: the
        # examples' colours are already where they belong, so nothing drifts towards the
        # voted map (whose windows at the charts' borders saw the padding: specks along
        # the borders); only the seams' steps are spread.
        scale = max(config.finish.blend_scale * float(np.sqrt(state.mask.sum())), 1.0)
        exemplars, source = state.made("exemplars"), state.made("source")
        copied = copy_through(exemplars, source)
        # The solve is on the atlas' grid: a seam's correction would spread over the
        # padding into the neighbouring charts. A chart without a seam keeps the copy.
        blended = seamless_copy(
            exemplars,
            source,
            copied,
            scale=scale,
            edge_support=config.finish.edge_support,
            edge_contrast=config.finish.edge_contrast,
            edge_floor=config.finish.edge_floor,
        )
        seamed = _charts_with_seams(source, state.mask)
        state.ycbcr = np.where(seamed[..., None], blended, copied).astype(np.float32)
        state.exemplars = None
        state.changed = (
            f"seams blended at scale {scale:.1f} px, the copy as reference; "
            f"{int((seamed & state.mask).sum())} texels in charts with a seam"
        )
        return state

    stages = (Stage("select", select), Stage("bands", bands), Stage("synthesize", engine))
    finish: tuple[Stage, ...] = FINISH_STAGES
    if same_texel:  # after the copy's source is made, before the seams are placed on it
        at = finish.index(COPY) + 1
        finish = (*finish[:at], Stage("same texel", same), *finish[at:])
        finish = tuple(Stage("blend", blend, BLEND.wanted) if f is BLEND else f for f in finish)
    start = time.perf_counter()
    ran = sized_config(config, query.mask)
    state, records = run_pipeline(
        SynthesisState(mask=query.mask, seed=seed, quiet=quiet), ran, stages + finish
    )
    working_image, source, engine_result = state.image, state.source, state.engine
    if working_image is None or source is None or engine_result is None:
        raise RuntimeError("uv-space synthesis: the pipeline made no texture (stage order)")
    # The texture at its own size: every texel copied from its example's full-resolution
    # texture, plus the finish's smooth correction (blend minus plain copy) of its texel.
    final_mask = covered_texels(uv, faces, size) if size != working else query.mask
    full = [np.asarray(e.texture)[..., :3] for e in chosen]
    if size == working and all(t.shape[:2] == (working, working) for t in full):
        image, fine_source = working_image, source
    else:
        used: list[np.ndarray | None] | None = None
        plain = copy_through(textures, source).astype(np.float32)
        # Outside the working mask the finish left 0: continued from the nearest texel,
        # for the output texels at the charts' borders that fall there.
        correction = fill_background(working_image - plain, query.mask)
        del plain
        if not same_texel:
            # A working texel at a chart's border is used, but some of its full-size texels
            # may not be (the example's padding): read on the surface there too.
            padded = [_surface_padded(e, t, working) for e, t in zip(chosen, full, strict=True)]
            full = [texture for texture, _ in padded]
            used = [mask for _, mask in padded]
        image, fine_source = fine_texture(full, source, correction, size, used=used)
    texture = fill_background(np.where(final_mask[..., None], image, 0.0), final_mask)
    seconds = time.perf_counter() - start
    log.info(
        "uv-space synthesis: %d^2 atlas (engine at %d^2) from %s in %.1f s",
        size,
        working,
        ", ".join(e.name for e in chosen),
        seconds,
    )
    cost = engine_result.cost
    return ColorizeResult(
        image=texture.astype(np.float32),
        mask=final_mask,
        source=fine_source,
        cost=cost,
        example_names=[e.name for e in chosen],
        objective=engine_result.objective,
        engine_timings=dict(engine_result.timings),
        config=ran,
        stages=records,
    )
