"""Texturing a mesh from synthesized views: projection UVs (one view) or a baked UV atlas.

**One view** (:func:`project_texture`): the UVs are the orthographic projection of
the vertices into the picture, and the synthesized map is the texture. Fallback for
what the view does not see: every face takes the colour of the visible texel it
projects onto (the nearest visible texel in the picture plane), so a hidden flank
shows the visible one mirrored and an occluded part the surface in front of it;
faces at the silhouette whose projection falls between pixel centres find the
texture's background filled with the nearest foreground colour, never black.

**Several views** (:func:`bake_views`): the mesh's own UVs, or an atlas made with
``xatlas`` when it has none. Each texel is a surface point; every view that sees
it (its depth within two pixels of the rendered surface) contributes its colour
with weight ``cos^2`` of the angle between the surface normal and the view
direction, times a feather that falls to zero within four pixels of the view's
silhouette and depth discontinuities, so views blend smoothly where they overlap.
Texels no view sees take the colour of the nearest seen texel in 3-D. Texels
outside every chart are filled with the nearest chart texel, so bilinear
filtering at chart seams never samples black.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from imagemap.io import InputError
from imagemap.mesh.files import textured_mesh
from imagemap.mesh.views import MeshRender, fill_from_nearest, sample_pixels

__all__ = ["bake_views", "project_texture", "rasterize_uv", "uv_atlas"]


def project_texture(mesh, render: MeshRender, image: np.ndarray):
    """The mesh textured with ``image`` seen from ``render``'s view (projection UVs).

    See the module notes for what hidden faces get.
    """
    image = np.asarray(image, dtype=np.float32)[..., :3]
    if image.shape[:2] != render.depth.shape:
        raise InputError(f"image {image.shape} does not match the render {render.depth.shape}")
    texture = fill_from_nearest(image, render.mask)
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
        import xatlas
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


def rasterize_uv(
    uv: np.ndarray, faces: np.ndarray, texture_size: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Texels of a square texture covered by UV triangles.

    Returns (texel flat indices (N,), face (N,), barycentrics (N, 3)); a texel
    (row i, column j) is covered when its centre ((j + 0.5) / T, 1 - (i + 0.5) / T)
    lies in the triangle; where triangles overlap, the lowest face index wins.
    """
    size = int(texture_size)
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
    face = np.repeat(np.arange(len(faces)), counts)
    start = np.cumsum(counts) - counts
    within = np.arange(counts.sum()) - np.repeat(start, counts)
    rows = row_lo[face] + within // np.maximum(n_cols[face], 1)
    cols = col_lo[face] + within % np.maximum(n_cols[face], 1)
    # Barycentrics of the texel centre in the face's UV triangle.
    ax, ay = px[face, 0], py[face, 0]
    v0x, v0y = px[face, 1] - ax, py[face, 1] - ay
    v1x, v1y = px[face, 2] - ax, py[face, 2] - ay
    qx, qy = cols - ax, rows - ay
    det = v0x * v1y - v1x * v0y
    ok = np.abs(det) > 1e-12
    safe = np.where(ok, det, 1.0)
    b1 = (qx * v1y - v1x * qy) / safe
    b2 = (v0x * qy - qx * v0y) / safe
    b0 = 1.0 - b1 - b2
    eps = 1e-9
    inside = ok & (b0 >= -eps) & (b1 >= -eps) & (b2 >= -eps)
    texel = rows[inside] * size + cols[inside]
    face, bary = face[inside], np.stack([b0, b1, b2], axis=1)[inside]
    order = np.lexsort((face, texel))
    first = order[np.r_[True, np.diff(texel[order]) != 0]] if order.size else order
    return texel[first], face[first], np.clip(bary[first], 0.0, 1.0)


#: A texel is seen by a view when it lies within this many pixels behind the
#: rendered surface.
VISIBILITY_PIXELS = 2.0
#: Weights fall to zero within this many pixels of a view's silhouette and
#: depth discontinuities.
FEATHER_PIXELS = 4.0


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


def bake_views(
    mesh,
    renders: list[MeshRender],
    images: list[np.ndarray],
    texture_size: int = 512,
):
    """Bake several views' maps into one UV atlas (see the module notes).

    Parameters
    ----------
    mesh : trimesh.Trimesh
        Its own UVs are used when it has them, else an xatlas atlas is made.
    renders : list of MeshRender
        One per view (from :func:`render_mesh` of this mesh).
    images : list of (H, W, 3) arrays
        The map synthesized for each view.
    texture_size : int
        Width and height of the texture.

    Returns
    -------
    trimesh.Trimesh with the atlas UVs and the baked texture.
    """
    from scipy.spatial import cKDTree

    if len(renders) != len(images) or not renders:
        raise InputError("bake_views: one image per view is needed")
    vertices, faces, uv, source = uv_atlas(mesh)
    normals = np.asarray(mesh.vertex_normals, dtype=np.float64)[source]
    texel, face, bary = rasterize_uv(uv, faces, texture_size)
    if texel.size == 0:
        raise InputError("the mesh's UV atlas covers no texel")
    corners = faces[face]
    position = np.einsum("nk,nkc->nc", bary, vertices[corners])
    normal = np.einsum("nk,nkc->nc", bary, normals[corners])
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-12)
    total = np.zeros((texel.size, 3), dtype=np.float64)
    weight = np.zeros(texel.size, dtype=np.float64)
    for render, image in zip(renders, images, strict=True):
        col, row, z = render.to_pixels(position)
        height, width = render.depth.shape
        ci = np.clip(np.round(col).astype(np.int64), 0, width - 1)
        ri = np.clip(np.round(row).astype(np.int64), 0, height - 1)
        inside = (col > -0.5) & (col < width - 0.5) & (row > -0.5) & (row < height - 0.5)
        surface = render.z[ri, ci]
        seen = inside & render.mask[ri, ci] & (z >= surface - VISIBILITY_PIXELS * render.pixel_size)
        facing = np.clip(normal @ render.view.direction, 0.0, 1.0) ** 2
        feather = np.clip(_view_edges(render)[ri, ci] / FEATHER_PIXELS, 1e-3, 1.0)
        w = np.where(seen, facing * feather, 0.0)
        filled = fill_from_nearest(np.asarray(image, dtype=np.float32)[..., :3], render.mask)
        colour = sample_pixels(filled, col, row)
        total += w[:, None] * colour
        weight += w
    seen = weight > 0
    colours = np.zeros((texel.size, 3), dtype=np.float64)
    colours[seen] = total[seen] / weight[seen, None]
    if seen.any() and not seen.all():
        # The documented fallback: the colour of the nearest seen texel in 3-D.
        _, nearest = cKDTree(position[seen]).query(position[~seen])
        colours[~seen] = colours[seen][nearest]
    texture = np.zeros((texture_size, texture_size, 3), dtype=np.float32)
    texture.reshape(-1, 3)[texel] = colours
    covered = np.zeros((texture_size, texture_size), dtype=bool)
    covered.flat[texel] = True
    texture = fill_from_nearest(texture, covered)
    return textured_mesh(vertices, faces, uv, texture)
