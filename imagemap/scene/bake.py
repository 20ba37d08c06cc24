"""Texturing a mesh from synthesized views: projection UVs (one view) or a baked UV atlas.

**One view** (:func:`project_texture`): the UVs are the orthographic projection of
the vertices into the picture, and the synthesized map is the texture. Fallback for
what the view does not see: every face takes the colour of the visible texel it
projects onto (the nearest visible texel in the picture plane), so a hidden flank
shows the visible one mirrored and an occluded part the surface in front of it;
faces at the silhouette whose projection falls between pixel centres find the
texture's background filled with the nearest foreground colour, never black.

**Several views** (:func:`bake_views`): the mesh's own UVs, or an atlas made with
``xatlas`` when it has none. Each texel is a surface point, and takes its colour
from the single view that sees it best (:func:`view_scores`: the largest cosine
between its normal and the view direction, with a margin at the view's silhouette
and depth jumps; seen = its depth within two pixels of the rendered surface). Two
views' syntheses of one part differ in detail, so an average of them ghosts: views
are blended only in a band two view pixels wide on each side of a boundary between
texels of different views (:func:`blend_chosen_views`); everywhere else a texel is
exactly one view's colour. Texels no view sees take the colour of the nearest seen
texel in 3-D. Texels outside every chart are filled with the nearest chart texel, so
bilinear filtering at chart seams never samples black. The texture's size is the
mesh's own texture's, else chosen from its texel density (:func:`texture_size_for`).
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from imagemap.core.blend import fill_background
from imagemap.io import InputError
from imagemap.materials import encode_normals, picture_normals_to_world
from imagemap.scene.files import textured_mesh
from imagemap.scene.views import (
    DEFAULT_MARGIN,
    DEFAULT_SIZE,
    MeshRender,
    View,
    parse_view,
    sample_pixels,
    texture_image,
)

__all__ = [
    "view_size_for",
    "bake_views",
    "blend_chosen_views",
    "covered_texels",
    "planar_barycentric",
    "project_texture",
    "rasterize_uv",
    "texture_size_for",
    "uv_atlas",
    "view_scores",
    "view_shares",
    "world_per_uv",
]


def project_texture(mesh, render: MeshRender, image: np.ndarray, *, texture_only: bool = False):
    """The mesh textured with ``image`` seen from ``render``'s view (projection UVs).

    See the module notes for what hidden faces get. With ``texture_only``, the texture
    alone (float32, not rounded to the 8 bits of a mesh's texture): for maps written
    at more bits than a texture holds, such as a 16-bit height map. ``image`` may be a
    whole factor finer than the render (the view copied at the texels' resolution,
    :mod:`imagemap.mesh.fineviews`): the texture is then that image, over the same
    picture (the projection UVs are in the picture's fractions).
    """
    image = np.asarray(image, dtype=np.float32)[..., :3]
    height, width = render.depth.shape
    fine = image.shape[0] // height if height else 0
    if fine < 1 or image.shape[:2] != (height * fine, width * fine):
        raise InputError(f"image {image.shape} does not match the render {render.depth.shape}")
    mask = np.repeat(np.repeat(render.mask, fine, axis=0), fine, axis=1)
    texture = fill_background(image, mask)
    if texture_only:
        return texture
    uv = render.projection_uv(np.asarray(mesh.vertices))
    return textured_mesh(mesh.vertices, mesh.faces, uv, texture)


# ------------------------------------------------------------------- UV atlases


def uv_atlas(mesh) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(vertices, faces, uv, source vertex index): the mesh's own UVs, else an xatlas atlas.

    The source index maps each output vertex to the input vertex it copies (xatlas
    splits vertices along chart seams).
    """
    uv = getattr(mesh.visual, "uv", None)
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    faces = np.asarray(mesh.faces, dtype=np.int64)
    if uv is not None and len(uv) == len(vertices):
        return vertices, faces, np.asarray(uv, dtype=np.float64), np.arange(len(vertices))
    try:
        import xatlas  # deferred: start-up: xatlas only for a mesh without UVs
    except ImportError as exc:
        raise InputError(
            "the mesh has no UV coordinates and xatlas is not installed "
            "(pip install xatlas, or give a mesh with UVs)"
        ) from exc
    vmapping, indices, uvs = xatlas.parametrize(
        vertices.astype(np.float32), faces.astype(np.uint32)
    )
    vmapping = vmapping.astype(np.int64)
    return vertices[vmapping], indices.astype(np.int64), uvs.astype(np.float64), vmapping


#: Texel candidates (a face's UV bounding box) examined at once by :func:`rasterize_uv`:
#: bounds its temporaries (about 100 bytes a candidate: 13 MB) whatever the atlas size. A
#: 1024^2 head atlas (3.4 M candidates) rasterizes as fast as in one piece (0.5 s).
RASTER_CHUNK = 1 << 17


def planar_barycentric(
    px: np.ndarray, py: np.ndarray, x: np.ndarray, y: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Barycentrics (N, 3) of points ``(x, y)`` (N,) in triangles of corners ``(px, py)``
    (N, 3) in a plane (UVs, pixels), unclipped; and where the triangle is not degenerate
    (elsewhere the barycentrics are meaningless).

    Examples
    --------
    >>> bary, ok = planar_barycentric(np.array([[0.0, 2, 0]]), np.array([[0.0, 0, 2]]),
    ...                               np.array([0.5]), np.array([1.0]))
    >>> bary.tolist(), ok.tolist()
    ([[0.25, 0.25, 0.5]], [True])
    """
    ax, ay = px[:, 0], py[:, 0]
    v0x, v0y = px[:, 1] - ax, py[:, 1] - ay
    v1x, v1y = px[:, 2] - ax, py[:, 2] - ay
    qx, qy = x - ax, y - ay
    det = v0x * v1y - v1x * v0y
    ok = np.abs(det) > 1e-12
    safe = np.where(ok, det, 1.0)
    b1 = (qx * v1y - v1x * qy) / safe
    b2 = (v0x * qy - qx * v0y) / safe
    return np.stack([1.0 - b1 - b2, b1, b2], axis=1), ok


def _raster_chunks(uv: np.ndarray, faces: np.ndarray, size: int):
    """(texel, face, barycentrics) of the texel centres inside UV triangles, chunk by chunk.

    Faces are taken in order, in chunks of about :data:`RASTER_CHUNK` candidate texels
    (a face's UV bounding box); within a chunk each texel once, by its lowest face.
    """
    faces = np.asarray(faces, dtype=np.int64)
    corners = np.asarray(uv, dtype=np.float64)[faces]  # (F, 3, 2)
    px = corners[..., 0] * size - 0.5  # continuous column (centre of j at j)
    py = (1.0 - corners[..., 1]) * size - 0.5
    col_lo = np.clip(np.ceil(px.min(axis=1)), 0, size - 1).astype(np.int64)
    col_hi = np.clip(np.floor(px.max(axis=1)), -1, size - 1).astype(np.int64)
    row_lo = np.clip(np.ceil(py.min(axis=1)), 0, size - 1).astype(np.int64)
    row_hi = np.clip(np.floor(py.max(axis=1)), -1, size - 1).astype(np.int64)
    n_cols = np.maximum(col_hi - col_lo + 1, 0)
    n_rows = np.maximum(row_hi - row_lo + 1, 0)
    counts = n_cols * n_rows
    bounds = np.searchsorted(np.cumsum(counts), np.arange(1, counts.sum() // RASTER_CHUNK + 1)
                             * RASTER_CHUNK)  # fmt: skip
    starts = np.unique(np.r_[0, bounds, len(faces)])
    for first_face, end_face in zip(starts[:-1], starts[1:], strict=True):
        chunk = np.arange(first_face, end_face)
        chunk_counts = counts[chunk]
        face = np.repeat(chunk, chunk_counts)
        start = np.cumsum(chunk_counts) - chunk_counts
        within = np.arange(chunk_counts.sum()) - np.repeat(start, chunk_counts)
        rows = row_lo[face] + within // np.maximum(n_cols[face], 1)
        cols = col_lo[face] + within % np.maximum(n_cols[face], 1)
        # Barycentrics of the texel centre in the face's UV triangle.
        bary, ok = planar_barycentric(px[face], py[face], cols, rows)
        eps = 1e-9
        inside = ok & np.all(bary >= -eps, axis=1)
        texel = rows[inside] * size + cols[inside]
        face, bary = face[inside], bary[inside]
        order = np.lexsort((face, texel))
        keep = order[np.r_[True, np.diff(texel[order]) != 0]] if order.size else order
        yield texel[keep], face[keep], bary[keep]


def rasterize_uv(
    uv: np.ndarray, faces: np.ndarray, texture_size: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Texels of a square texture covered by UV triangles.

    Returns (texel flat indices (N,), face (N,), barycentrics (N, 3)), by texel; a
    texel (row i, column j) is covered when its centre ((j + 0.5) / T, 1 - (i + 0.5) / T)
    lies in the triangle; where triangles overlap, the lowest face index wins.

    Examples
    --------
    >>> texel, face, bary = rasterize_uv(np.array([[0, 0], [1, 0], [0, 1.0]]),
    ...                                  np.array([[0, 1, 2]]), 4)
    >>> texel.tolist()  # the lower-left half of a 4 x 4 texture, diagonal included
    [0, 4, 5, 8, 9, 10, 12, 13, 14, 15]
    """
    size = int(texture_size)
    owned = np.zeros(size * size, dtype=bool)
    found = []
    # A chunk's faces all come after the previous chunk's: a texel keeps the first chunk's.
    for texel, face, bary in _raster_chunks(uv, faces, size):
        new = ~owned[texel]
        owned[texel[new]] = True
        found.append((texel[new], face[new], bary[new]))
    texel = np.concatenate([f[0] for f in found])
    face = np.concatenate([f[1] for f in found])
    bary = np.concatenate([f[2] for f in found])
    order = np.argsort(texel, kind="stable")
    return texel[order], face[order], np.clip(bary[order], 0.0, 1.0)


def covered_texels(uv: np.ndarray, faces: np.ndarray, texture_size: int) -> np.ndarray:
    """(T, T) bool: the texels :func:`rasterize_uv` covers, without its per-texel arrays.

    Examples
    --------
    >>> int(covered_texels(np.array([[0, 0], [1, 0], [0, 1.0]]), np.array([[0, 1, 2]]), 4).sum())
    10
    """
    size = int(texture_size)
    mask = np.zeros(size * size, dtype=bool)
    for texel, _, _ in _raster_chunks(uv, faces, size):
        mask[texel] = True
    return mask.reshape(size, size)


#: A texel is seen by a view when it lies within this many pixels behind the
#: rendered surface.
VISIBILITY_PIXELS = 2.0
#: A view's claim on a texel falls to zero within this many pixels of its silhouette
#: and depth discontinuities (a margin: colours there mix object and background, and
#: the depth test is least sure).
FEATHER_PIXELS = 4.0
#: Half-width, in pixels of the views, of the band around a boundary between two
#: views' texels in which their colours are blended; elsewhere every texel is one
#: view's colour. Two pixels hide the step between two views' syntheses of the same
#: part and blur nothing else (at 4 px the fish's stripes doubled along the seams).
SEAM_BAND_PIXELS = 2.0
#: Texels per view pixel (along each axis) of an atlas sized from the texel density: the
#: bilinear lookups of the views' maps then lose nothing to the atlas.
TEXELS_PER_PIXEL = 2.0
#: Bounds of an atlas sized from the texel density (a power of two in between).
MIN_TEXTURE_SIZE = 64
MAX_TEXTURE_SIZE = 4096


def _view_edges(render: MeshRender) -> np.ndarray:
    """Distance in pixels to the nearest silhouette or depth discontinuity of a view."""
    z = np.where(render.mask, render.z, np.nan)
    jump = 3.0 * render.pixel_size
    edge = ~render.mask
    dz_y = np.abs(np.diff(z, axis=0)) > jump
    dz_x = np.abs(np.diff(z, axis=1)) > jump
    edge[:-1] |= dz_y
    edge[1:] |= dz_y
    edge[:, :-1] |= dz_x
    edge[:, 1:] |= dz_x
    if not edge.any():
        return np.full(edge.shape, np.inf)
    return ndimage.distance_transform_edt(~edge)


def world_per_uv(vertices: np.ndarray, faces: np.ndarray, uv: np.ndarray) -> float:
    """Surface area per unit of UV area (world units^2): the atlas' mean texel density.

    Examples
    --------
    >>> square = np.array([[0, 0, 0], [2, 0, 0], [2, 2, 0], [0, 2, 0.0]])
    >>> world_per_uv(square, np.array([[0, 1, 2], [0, 2, 3]]), square[:, :2] / 4)
    16.0
    """
    corners = np.asarray(vertices, dtype=np.float64)[faces]
    area = 0.5 * np.linalg.norm(
        np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1
    )
    flat = np.asarray(uv, dtype=np.float64)[faces]
    e1, e2 = flat[:, 1] - flat[:, 0], flat[:, 2] - flat[:, 0]
    uv_area = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    total_uv = float(uv_area.sum())
    if not np.isfinite(total_uv) or not np.isfinite(area.sum()):
        raise InputError("the mesh's vertices or UV coordinates have NaN or infinite values")
    if total_uv <= 0:
        raise InputError("the mesh's UV triangles have no area")
    return float(area.sum()) / total_uv


def texture_size_for(mesh, pixel_size: float | None = None) -> int:
    """The side of the mesh's texture: its own texture's, else one from the texel density.

    A mesh with a texture keeps its size (the larger side; a texture smaller than
    :data:`MIN_TEXTURE_SIZE` does not count). Otherwise the atlas gets
    :data:`TEXELS_PER_PIXEL` texels per ``pixel_size`` (the views' world units per
    pixel) along each axis, rounded up to a power of two within
    [:data:`MIN_TEXTURE_SIZE`, :data:`MAX_TEXTURE_SIZE`]; 512 without a pixel size.

    Examples
    --------
    >>> import trimesh
    >>> plane = trimesh.creation.box(extents=(2.0, 2.0, 0.01))  # UVs over 2 x 2 units
    >>> plane.visual = trimesh.visual.TextureVisuals(uv=plane.vertices[:, :2] / 2 + 0.5)
    >>> texture_size_for(plane, pixel_size=0.01)  # 2 / 0.01 * 2 = 400 texels -> 512
    512
    """

    own = texture_image(mesh) if getattr(mesh.visual, "uv", None) is not None else None
    # A texture smaller than an atlas can be is a placeholder (trimesh gives a mesh with
    # UVs and no image a 2 x 2 one) or a swatch of flat colours: sized from the density.
    if own is not None and max(own.shape[:2]) >= MIN_TEXTURE_SIZE:
        return int(max(own.shape[:2]))
    if pixel_size is None or pixel_size <= 0:
        return 512
    vertices, faces, uv, _ = uv_atlas(mesh)
    wanted = TEXELS_PER_PIXEL * np.sqrt(world_per_uv(vertices, faces, uv)) / pixel_size
    size = 2 ** int(np.ceil(np.log2(max(wanted, 1.0))))
    return int(np.clip(size, MIN_TEXTURE_SIZE, MAX_TEXTURE_SIZE))


#: The most pixels a view gets by :func:`view_size_for` (the default ``--size``): 2.5x
#: :data:`~imagemap.scene.views.DEFAULT_SIZE`'s, 317x237. The exact rule asks more of a
#: fine atlas (the 2 m fish of issue #46 at 512^2: 734x550, 13x the pixels, one texel per
#: pixel); the cap holds that fish to 1.38x its time at 200x150 in a quiet run, 1.53-1.65x at
#: load 9 on the shared 2-core machine (docs/meshes.md).
MAX_VIEW_PIXELS = 5 * DEFAULT_SIZE[0] * DEFAULT_SIZE[1] // 2


def view_size_for(
    mesh,
    views,
    texture_size: int | None,
    base: tuple[int, int] = DEFAULT_SIZE,
    max_pixels: int = MAX_VIEW_PIXELS,
) -> tuple[int, int]:
    """Each view's size (width, height) so that one view pixel covers no more of the
    surface than one texel of the atlas it is baked into (the default ``--size``).

    A view coarser than the texels it fills draws its pixels' steps into the texture
    (issue #46: a stair-stepped gill line and seam at 512^2). The texel's side on the
    surface is ``sqrt(world area / UV area) / texture_size``; each view's pixel is its
    extent across the picture over the size (as :func:`render_mesh` frames it). ``base``
    is scaled up (never down, its aspect kept) until the coarsest of ``views`` is that
    fine, but to at most ``max_pixels`` pixels (the time grows with them).

    Parameters
    ----------
    mesh : trimesh.Trimesh
        With UV coordinates (without them: ``base``).
    views : list of View or str
        The views (with ``--views auto``: the candidates).
    texture_size : int or None
        The atlas's side; None: the mesh's own texture's, and ``base`` when it has none
        (the atlas is then sized from the views, :func:`texture_size_for`).

    Examples
    --------
    >>> import trimesh
    >>> plane = trimesh.creation.box(extents=(2.0, 2.0, 0.01))  # UVs over 2 x 2 units
    >>> plane.visual = trimesh.visual.TextureVisuals(uv=plane.vertices[:, :2] / 2 + 0.5)
    >>> view_size_for(plane, ["front"], 64)  # texels of ~2/64: 200x150 is finer already
    (200, 150)
    >>> view_size_for(plane, ["front"], 200)  # pixels of 2 / (150 * 0.84), texels of ~2/200
    (316, 237)
    >>> view_size_for(plane, ["front"], 4096)  # the cap: 2.5x the base's pixels
    (317, 238)
    """
    base = (int(base[0]), int(base[1]))
    if texture_size is None:
        own = texture_image(mesh) if getattr(mesh.visual, "uv", None) is not None else None
        if own is None or max(own.shape[:2]) < MIN_TEXTURE_SIZE:
            return base
        texture_size = int(max(own.shape[:2]))
    try:
        vertices, faces, uv, _ = uv_atlas(mesh)
        texel = float(np.sqrt(world_per_uv(vertices, faces, uv))) / int(texture_size)
    except (InputError, AttributeError):  # no usable UVs: nothing to be fine for
        return base
    points = np.asarray(mesh.vertices, dtype=np.float64)
    usable = 1.0 - 2.0 * DEFAULT_MARGIN
    pixel = 0.0
    for view in views:
        view = view if isinstance(view, View) else parse_view(view)
        extent = np.ptp(points @ view.rotation().T, axis=0)
        pixel = max(pixel, extent[0] / (base[0] * usable), extent[1] / (base[1] * usable))
    factor = pixel / texel if texel > 0 else 1.0
    factor = min(factor, float(np.sqrt(max_pixels / (base[0] * base[1]))))
    if factor <= 1.0:
        return base
    return (int(np.ceil(base[0] * factor - 1e-9)), int(np.ceil(base[1] * factor - 1e-9)))


def view_scores(
    render: MeshRender, position: np.ndarray, normal: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """How well a view sees surface points: (score (N,), column (N,), row (N,)).

    The score is the cosine between the normal and the view direction, times a margin
    that falls from 1 to 0 within :data:`FEATHER_PIXELS` of the view's silhouette and
    depth jumps; 0 where the view does not see the point (outside the picture, on the
    background, or more than :data:`VISIBILITY_PIXELS` behind the rendered surface).
    """
    col, row, z = render.to_pixels(position)
    height, width = render.depth.shape
    ci = np.clip(np.round(col).astype(np.int64), 0, width - 1)
    ri = np.clip(np.round(row).astype(np.int64), 0, height - 1)
    inside = (col > -0.5) & (col < width - 0.5) & (row > -0.5) & (row < height - 0.5)
    surface = render.z[ri, ci]
    seen = inside & render.mask[ri, ci] & (z >= surface - VISIBILITY_PIXELS * render.pixel_size)
    facing = np.clip(normal @ render.view.direction, 0.0, 1.0)
    margin = np.clip(_view_edges(render)[ri, ci] / FEATHER_PIXELS, 1e-3, 1.0)
    return np.where(seen & (facing > 0), facing * margin, 0.0), col, row


def view_shares(mesh, renders: list[MeshRender]) -> np.ndarray:
    """The share of the surface (by area) each view sees best (:func:`view_scores`).

    What each view will give the baked texture; faces no view sees count for none.

    Examples
    --------
    >>> import trimesh
    >>> from imagemap.scene.views import render_mesh
    >>> sphere = trimesh.creation.icosphere(subdivisions=3)
    >>> shares = view_shares(sphere, [render_mesh(sphere, v, (48, 48)) for v in ("front", "back")])
    >>> [round(float(s), 1) for s in shares]
    [0.5, 0.5]
    """
    triangles = np.asarray(mesh.triangles, dtype=np.float64)
    cross = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    area = 0.5 * np.linalg.norm(cross, axis=1)
    normal = cross / np.maximum(2.0 * area[:, None], 1e-300)
    centre = triangles.mean(axis=1)
    scores = np.stack([view_scores(render, centre, normal)[0] for render in renders])
    best = np.argmax(scores, axis=0)
    seen = scores.max(axis=0) > 0
    shares = np.bincount(best[seen], weights=area[seen], minlength=len(renders))
    total = shares.sum()
    return shares / total if total > 0 else np.full(len(renders), 1.0 / len(renders))


def _tent(values: np.ndarray, radius: int) -> np.ndarray:
    """Two box filters of width ``2 radius + 1``: a tent of support ``2 radius`` texels
    each way (exactly 0 beyond it, exactly the input's constant inside a constant area
    but for rounding)."""
    size = 2 * int(radius) + 1
    out = ndimage.uniform_filter(values, size=size, mode="constant")
    return ndimage.uniform_filter(out, size=size, mode="constant")


def blend_chosen_views(
    colours: np.ndarray,
    scores: np.ndarray,
    texel: np.ndarray,
    texture_size: int,
    band: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Each texel the colour of its best view, blended only near boundaries between views.

    Parameters
    ----------
    colours : (V, N, C) array
        Each view's colour at each texel.
    scores : (V, N) array
        Each view's :func:`view_scores` at each texel (0: not seen).
    texel : (N,) int array
        The texels' flat indices in the ``texture_size``^2 atlas.
    texture_size : int
    band : float
        Half-width of the blending band, in texels (0: no blending).

    Returns
    -------
    (colour (N, C), chosen view (N,); -1 where no view sees the texel)

    Examples
    --------
    Two views that disagree (0 and 1) over a strip of 12 texels, each best on its half:

    >>> scores = np.array([[1.0] * 6 + [0.5] * 6, [0.5] * 6 + [1.0] * 6])
    >>> colours = np.stack([np.zeros((12, 1)), np.ones((12, 1))])
    >>> colour, view = blend_chosen_views(colours, scores, np.arange(12), 12, band=2)
    >>> view.tolist()
    [0, 0, 0, 0, 0, 0, 1, 1, 1, 1, 1, 1]
    >>> colour[:, 0].round(2).tolist()  # one view's colour but within 2 texels of the seam
    [0.0, 0.0, 0.0, 0.0, 0.11, 0.33, 0.67, 0.89, 1.0, 1.0, 1.0, 1.0]
    """
    n_views, n = scores.shape
    best = np.argmax(scores, axis=0)
    seen = scores.max(axis=0) > 0
    chosen = np.where(seen, best, -1)
    colour = colours[np.maximum(best, 0), np.arange(n)].astype(np.float64)
    radius = int(np.ceil(band / 2.0))
    if radius < 1 or n_views < 2 or not seen.any():
        return colour, chosen
    covered = np.zeros(texture_size * texture_size)
    covered[texel[seen]] = 1.0
    support = _tent(covered.reshape(texture_size, texture_size), radius).reshape(-1)[texel]
    weights = np.zeros((n_views, n))
    for view in range(n_views):
        indicator = np.zeros(texture_size * texture_size)
        indicator[texel[chosen == view]] = 1.0
        spread = _tent(indicator.reshape(texture_size, texture_size), radius).reshape(-1)
        # Only a view that sees the texel may lend it colour.
        weights[view] = np.where(scores[view] > 0, spread[texel] / np.maximum(support, 1e-12), 0)
    # Rounding in the box filters: a weight within 1e-6 of 0 is 0 (beyond the band).
    weights[weights < 1e-6] = 0.0
    total = weights.sum(axis=0)
    mixed = seen & (total > 0) & (weights.max(axis=0) < total * (1.0 - 1e-6))
    if mixed.any():
        blend = np.einsum("vn,vnc->nc", weights[:, mixed], colours[:, mixed]) / total[mixed, None]
        colour[mixed] = blend
    return colour, chosen


def bake_views(
    mesh,
    renders: list[MeshRender],
    images: list[np.ndarray],
    texture_size: int | None = None,
    *,
    seam_band: float = SEAM_BAND_PIXELS,
    return_views: bool = False,
    texture_only: bool = False,
    picture_normals: bool = False,
):
    """Bake several views' maps into one UV atlas (see the module notes).

    Parameters
    ----------
    mesh : trimesh.Trimesh
        Its own UVs are used when it has them, else an xatlas atlas is made.
    renders : list of MeshRender
        One per view (from :func:`render_mesh` of this mesh).
    images : list of (H, W, 3) arrays
        The map synthesized for each view (or copied at a whole factor of its view's
        size, :func:`imagemap.mesh.fineviews.fine_view`: sampled at the same points).
    texture_size : int, optional
        Width and height of the texture; default :func:`texture_size_for` the mesh at
        the views' pixel size.
    seam_band : float
        Half-width (view pixels) of the band in which two views' colours are blended.
    return_views : bool
        Also return the view chosen for each texel ((T, T) int, -1 where no view sees
        the texel or outside the charts).
    texture_only : bool
        Return the texture alone ((T, T, 3) float32, not rounded to a texture's 8 bits;
        the atlas is the one the same call makes without it): for maps written at more
        bits, such as a 16-bit height map.
    picture_normals : bool
        ``images`` are tangent-space normals (encoded) in each view's picture frame (the
        picture's x and y laid on the surface, :func:`imagemap.materials.view_normals_to_atlas`):
        each texel's sample is turned into a world direction in the frame at the texel's
        own surface normal before the views are blended; the texture holds world normals
        (encoded).

    Returns
    -------
    trimesh.Trimesh with the atlas UVs and the baked texture (and the chosen views).
    """
    from scipy.spatial import (
        cKDTree,
    )  # deferred: start-up: scipy.spatial only where a k-d tree is built

    if len(renders) != len(images) or not renders:
        raise InputError("bake_views: one image per view is needed")
    pixel_size = min(render.pixel_size for render in renders)
    if texture_size is None:
        texture_size = texture_size_for(mesh, pixel_size)
    vertices, faces, uv, source = uv_atlas(mesh)
    normals = np.asarray(mesh.vertex_normals, dtype=np.float64)[source]
    texel, face, bary = rasterize_uv(uv, faces, texture_size)
    if texel.size == 0:
        raise InputError("the mesh's UV atlas covers no texel")
    corners = faces[face]
    position = np.einsum("nk,nkc->nc", bary, vertices[corners])
    normal = np.einsum("nk,nkc->nc", bary, normals[corners])
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-12)
    scores = np.zeros((len(renders), texel.size))
    colours = np.zeros((len(renders), texel.size, 3), dtype=np.float32)
    for k, (render, image) in enumerate(zip(renders, images, strict=True)):
        scores[k], col, row = view_scores(render, position, normal)
        # An image a whole factor finer than its view (the final copy at the texels'
        # resolution, imagemap.mesh.fineviews) is sampled at the same points.
        fine = max(1, int(np.shape(image)[0]) // render.depth.shape[0])
        if fine > 1:
            col, row = (col + 0.5) * fine - 0.5, (row + 0.5) * fine - 0.5
        mask = np.repeat(np.repeat(render.mask, fine, axis=0), fine, axis=1)
        filled = fill_background(np.asarray(image, dtype=np.float32)[..., :3], mask)
        colours[k] = sample_pixels(filled, col, row)
        if picture_normals:
            world = picture_normals_to_world(colours[k], render.view.rotation(), normal)
            colours[k] = encode_normals(world)
    texel_world = np.sqrt(world_per_uv(vertices, faces, uv)) / texture_size
    band = seam_band * pixel_size / texel_world
    colours_out, chosen = blend_chosen_views(colours, scores, texel, texture_size, band)
    seen = chosen >= 0
    if seen.any() and not seen.all():
        # The documented fallback: the colour of the nearest seen texel in 3-D.
        _, nearest = cKDTree(position[seen]).query(position[~seen])
        colours_out[~seen] = colours_out[seen][nearest]
    texture = np.zeros((texture_size, texture_size, 3), dtype=np.float32)
    texture.reshape(-1, 3)[texel] = colours_out
    covered = np.zeros((texture_size, texture_size), dtype=bool)
    covered.flat[texel] = True
    texture = fill_background(texture, covered)
    if texture_only:
        return texture
    textured = textured_mesh(vertices, faces, uv, texture)
    if not return_views:
        return textured
    views = np.full((texture_size, texture_size), -1, dtype=np.int64)
    views.flat[texel] = chosen
    return textured, views
