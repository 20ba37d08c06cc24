"""PBR maps on the mesh route: each view's maps copied through its source map and baked
through the colour's own bake (:func:`with_mesh_maps`), normals turned into the atlas'
tangent frame."""

from __future__ import annotations

import numpy as np

from imagemap.materials import (
    MIN_NORMAL_Z,
    NEUTRAL,
    SIDE_MAPS,
    _picture_frame,
    _surface_normals,
    decode_normals,
    encode_normals,
    transfer_maps,
)
from imagemap.scene.bake import rasterize_uv
from imagemap.scene.files import _base_colour_texture, material_of, textured_mesh
from imagemap.scene.views import fill_from_nearest
from imagemap.tangents import corner_tangents, tangent_frames

__all__ = ["SIDE_MAPS", "bake_maps", "mesh_maps", "with_mesh_maps", "with_surface_maps"]


def _baked(out, what: str = "bake_maps: bake's result") -> np.ndarray:
    """A bake's texture: the array itself (``texture_only`` bakes, not rounded to 8 bits)
    or a textured mesh's base colour."""
    if isinstance(out, np.ndarray):
        return np.asarray(out, dtype=np.float32)
    return _base_colour_texture(out, what)


def bake_maps(
    mesh, renders: list, view_maps: list[dict], bake, textured, projection: bool = False
) -> dict:
    """The mesh route's maps: each view's maps baked into the colour's atlas.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        The query mesh the views were rendered from.
    renders : list of MeshRender
        One per view.
    view_maps : list of dict
        Per view, :func:`transfer_maps` of its result (picture frame).
    bake : callable (list of (H, W, 3) images) -> textured trimesh or (T, T, 3) array
        The bake that made the colour's texture (same atlas for any images); one that
        returns the texture itself keeps the maps' precision (a 16-bit height map).
    textured : trimesh.Trimesh
        The mesh the maps are for: its UVs, vertex normals and MikkTSpace tangents
        give the normal map's tangent frames (the colour's textured mesh, or the
        mesh as written, :func:`imagemap.scene.surface.kept_geometry`: same UVs).
    projection : bool
        ``bake`` projects one view (projection UVs, the texture is the view's picture).

    Returns
    -------
    dict of texture-sized maps, as :func:`imagemap.mesh.textured_mesh` takes them.
    """

    grey = ("roughness", "metallic", "ao", "height")
    kinds = [k for k in grey if any(k in m for m in view_maps)]
    out: dict[str, np.ndarray] = {}
    for start in range(0, len(kinds), 3):  # three grey maps per bake
        group = kinds[start : start + 3]
        images = []
        for maps, render in zip(view_maps, renders, strict=True):
            packed = np.zeros(render.depth.shape + (3,), dtype=np.float32)
            for channel, kind in enumerate(group):
                packed[..., channel] = maps.get(kind, NEUTRAL[kind][0])
            images.append(packed)
        baked = _baked(bake(images))
        for channel, kind in enumerate(group):
            out[kind] = baked[..., channel]
    if any("normal" in m for m in view_maps):
        out["normal"] = _baked_normals(mesh, renders, view_maps, bake, textured, projection)
    return out


def _world_normals(mesh, render, maps: dict) -> np.ndarray:
    """A view's normal map turned into world directions at its pixels (H, W, 3); +z
    where the view sees nothing or has no normal map."""
    world = np.zeros(render.depth.shape + (3,), dtype=np.float64)
    world[..., 2] = 1.0
    pixels = np.flatnonzero(render.mask)
    if "normal" in maps and pixels.size:
        faces = render.face.flat[pixels]
        bary = render.barycentric.reshape(-1, 3)[pixels].astype(np.float64)
        normals = _surface_normals(mesh, faces, bary)
        local = decode_normals(maps["normal"].reshape(-1, 3)[pixels]).astype(np.float64)
        p_t, p_b = _picture_frame(render.view.rotation(), normals)
        vectors = local[:, :1] * p_t + local[:, 1:2] * p_b + local[:, 2:] * normals
        world.reshape(-1, 3)[pixels] = vectors
    return world


def _to_tangent_space(world: np.ndarray, textured, face: np.ndarray, bary: np.ndarray):
    """World normals (N, 3) at surface points of ``textured`` in its MikkTSpace frames
    (the frames its GLB's ``TANGENT`` gives a renderer), unit; flat where a normal
    leans more than :data:`MIN_NORMAL_Z` allows from its surface."""
    tangents = corner_tangents(
        textured.vertices, textured.faces, textured.vertex_normals, textured.visual.uv
    )
    frame = tangent_frames(tangents, textured.vertex_normals, textured.faces, face, bary)
    local = np.stack([np.einsum("ij,ij->i", world, v) for v in frame], axis=1)
    local /= np.maximum(np.linalg.norm(local, axis=1, keepdims=True), 1e-12)
    # A texel whose baked normal leans too far from its surface came from another
    # surface (a hidden fin back filled from its front): flat there.
    local[local[:, 2] < MIN_NORMAL_Z] = (0.0, 0.0, 1.0)
    return local


def _baked_normals(mesh, renders, view_maps, bake, textured, projection: bool) -> np.ndarray:
    """The views' normal maps as one tangent-space normal texture of ``textured``'s UVs,
    in the frames of its MikkTSpace tangents (:func:`imagemap.tangents.mikk_tangents`,
    what :func:`~imagemap.scene.files.export_textured` writes as ``TANGENT``).

    Each view's normals go to world directions, through the colour's ``bake``, and
    into the tangent frame at each texel's surface point. With ``projection`` (one
    view, its projection UVs) texels are the view's pixels: each takes the frame at
    the surface point the view sees there.
    """
    pairs = zip(renders, view_maps, strict=True)
    images = [encode_normals(_world_normals(mesh, render, maps)) for render, maps in pairs]
    baked = _baked(bake(images))
    if projection:
        render = renders[0]
        texel = np.flatnonzero(render.mask)
        face = render.face.flat[texel]
        bary = render.barycentric.reshape(-1, 3)[texel].astype(np.float64)
    else:
        texel, face, bary = rasterize_uv(
            np.asarray(textured.visual.uv), textured.faces, baked.shape[0]
        )
    world = decode_normals(baked.reshape(-1, 3)[texel]).astype(np.float64)
    local = _to_tangent_space(world, textured, face, bary)
    texture = np.zeros(baked.shape[:2] + (3,), dtype=np.float32)
    texture[..., 2] = 1.0
    texture.reshape(-1, 3)[texel] = local
    covered = np.zeros(baked.shape[:2], dtype=bool)
    covered.flat[texel] = True
    return encode_normals(fill_from_nearest(texture, covered))


def mesh_maps(
    textured, mesh, renders: list, results: list, databases: list, bake, projection=False
) -> dict[str, np.ndarray]:
    """The examples' maps baked beside the colour of the mesh route: every kind an
    example used has, ``"height"`` among them (see :data:`SIDE_MAPS`); empty when no
    example used has a map. Parameters as :func:`with_mesh_maps`."""
    view_maps = [transfer_maps(r, db) for r, db in zip(results, databases, strict=True)]
    if not any(view_maps):
        return {}
    return bake_maps(mesh, renders, view_maps, bake, textured, projection)


def with_surface_maps(textured, maps: dict[str, np.ndarray]):
    """``textured`` with ``maps`` (normal, roughness, metallic, ao) in its material;
    ``textured`` itself when there are none."""
    if not maps:
        return textured
    return textured_mesh(
        textured.vertices,
        textured.faces,
        textured.visual.uv,
        _base_colour_texture(textured, "with_mesh_maps: textured"),
        normals=np.asarray(textured.vertex_normals),
        maps=maps,
        material=material_of(textured),
    )


def with_mesh_maps(
    textured, mesh, renders: list, results: list, databases: list, bake, projection=False
):
    """The mesh route's textured mesh with the examples' maps baked beside its colour.

    Each view's maps come through its result's source map (:func:`transfer_maps`),
    then go through the same ``bake`` as the colour (:func:`bake_maps`). Returns
    ``textured`` itself when no example used has a map. A height map has no place in
    a glTF material and is left out (:func:`mesh_maps` gives it).

    Parameters
    ----------
    textured : trimesh.Trimesh
        The colour's textured mesh.
    mesh : trimesh.Trimesh
        The query mesh.
    renders, results, databases : lists, one entry per view
        The views' renders, :class:`~imagemap.depth.pipeline.ColorizeResult` and the
        databases they were made from.
    bake : callable (list of images) -> textured trimesh or texture array
        The colour's bake, e.g. ``lambda images: bake_views(mesh, renders, images, size)``.
    projection : bool
        One view projected (``project_texture``) rather than baked into an atlas.
    """
    maps = mesh_maps(textured, mesh, renders, results, databases, bake, projection)
    return with_surface_maps(textured, {k: v for k, v in maps.items() if k not in SIDE_MAPS})
