"""PBR maps on the mesh route, carried from the examples by the colour's own choices.

- **Views path**: each view's maps copied through its source map and baked through the
  colour's own bake (:func:`with_mesh_maps`), normals turned into the atlas' tangent frame.
- **uv-space and registered paths** (:func:`atlas_maps`): every texel of the texture says
  which example and which texel its colour came from (the result's source map); the
  examples' normal, roughness, metallic and ao maps are read at the same place, so they
  stay in register with the colour. On the uv-space path that place is in the example's
  own atlas (the query's layout): its tangent-space normals copy as they are. On the
  registered path it is the example's surface point resampled into the query's atlas
  (:attr:`imagemap.mesh.register.Resampled.correspondence`): the example's normals are
  turned into world directions (its MikkTSpace frames), by the registration, onto the
  query's surface normal there (the relief is relative to the surface) and into the
  frames of the mesh as written.
"""

from __future__ import annotations

import numpy as np

from imagemap.core.blend import fill_background
from imagemap.materials import (
    MAP_KINDS,
    MIN_NORMAL_Z,
    NEUTRAL,
    SIDE_MAPS,
    _surface_normals,
    decode_normals,
    encode_normals,
    picture_normals_to_world,
    transfer_maps,
)
from imagemap.scene.bake import rasterize_uv
from imagemap.scene.files import (
    _base_colour_texture,
    _material_maps,
    material_of,
    textured_mesh,
)
from imagemap.scene.views import sample_image
from imagemap.tangents import corner_tangents, tangent_frames

__all__ = [
    "SIDE_MAPS",
    "atlas_maps",
    "bake_maps",
    "mesh_maps",
    "with_mesh_maps",
    "with_surface_maps",
]

#: The maps a glTF material holds that the atlas paths carry (a mesh example's material
#: has no height slot: :data:`SIDE_MAPS` are not read from mesh examples).
ATLAS_KINDS = ("normal", "roughness", "metallic", "ao")


def _baked(out, what: str = "bake_maps: bake's result") -> np.ndarray:
    """A bake's texture: the array itself (``texture_only`` bakes, not rounded to 8 bits)
    or a textured mesh's base colour."""
    if isinstance(out, np.ndarray):
        return np.asarray(out, dtype=np.float32)
    return _base_colour_texture(out, what)


def bake_maps(
    mesh,
    renders: list,
    view_maps: list[dict],
    bake,
    textured,
    projection: bool = False,
    bake_normals=None,
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
    bake_normals : callable, optional
        The same bake of the views' picture-frame normals into world normals at each
        texel's own surface normal (``bake_views(..., picture_normals=True)``); the maps
        may then be finer than their views (the fine copy). Without it, each view's
        normals are turned into world directions at its pixels' surface points first.

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
            # A view's maps at its size, or copied at a whole factor of it (fineviews).
            shape = np.shape(next(iter(maps.values())))[:2] if maps else render.depth.shape
            packed = np.zeros(shape + (3,), dtype=np.float32)
            for channel, kind in enumerate(group):
                packed[..., channel] = maps.get(kind, NEUTRAL[kind][0])
            images.append(packed)
        baked = _baked(bake(images))
        for channel, kind in enumerate(group):
            out[kind] = baked[..., channel]
    if any("normal" in m for m in view_maps):
        out["normal"] = _baked_normals(
            mesh, renders, view_maps, bake, textured, projection, bake_normals
        )
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
        encoded = maps["normal"].reshape(-1, 3)[pixels]
        world.reshape(-1, 3)[pixels] = picture_normals_to_world(
            encoded, render.view.rotation(), normals
        )
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


def _baked_normals(
    mesh, renders, view_maps, bake, textured, projection: bool, bake_normals=None
) -> np.ndarray:
    """The views' normal maps as one tangent-space normal texture of ``textured``'s UVs,
    in the frames of its MikkTSpace tangents (:func:`imagemap.tangents.mikk_tangents`,
    what :func:`~imagemap.scene.files.export_textured` writes as ``TANGENT``).

    Each view's normals go to world directions (at its pixels' surface points, or with
    ``bake_normals`` at each texel's own), through the colour's bake, and into the
    tangent frame at each texel's surface point. With ``projection`` (one
    view, its projection UVs) texels are the view's pixels: each takes the frame at
    the surface point the view sees there.
    """
    if bake_normals is not None and not projection:
        flat = np.asarray(NEUTRAL["normal"], dtype=np.float32)
        images = []
        for maps in view_maps:  # a view without a normal map: flat, its surface's own
            shape = np.shape(next(iter(maps.values())))[:2]
            images.append(
                maps["normal"] if "normal" in maps else np.broadcast_to(flat, shape + (3,))
            )
        baked = _baked(bake_normals(images))
    else:
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
    return encode_normals(fill_background(texture, covered))


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


def _example_mesh(example):
    """The mesh an atlas example's maps are read from: a registered example's own mesh
    (its ``mesh`` is the query's), else the example's."""
    own = getattr(example, "example_mesh", None)
    return own if own is not None else example.mesh


def _rotate_onto(vectors: np.ndarray, start: np.ndarray, end: np.ndarray) -> np.ndarray:
    """``vectors`` (N, 3) turned by the least rotation taking unit ``start`` onto unit
    ``end`` (rows); where the two are opposite, ``end`` itself (flat).

    Examples
    --------
    >>> x, y, z = np.eye(3)
    >>> _rotate_onto(np.array([[0.6, 0.0, 0.8]]), z[None], x[None]).round(6).tolist()
    [[0.8, 0.0, -0.6]]
    """
    w = np.cross(start, end)
    c = np.einsum("ij,ij->i", start, end)[:, None]
    wv = np.cross(w, vectors)
    turned = vectors + wv + np.cross(w, wv) / np.maximum(1.0 + c, 1e-12)
    return np.where(1.0 + c > 1e-6, turned, end)


def _query_texels(frames, size: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The written mesh's used texels at ``size``: (texel, face, barycentrics, unit
    normal (N, 3) as a renderer interpolates it)."""
    texel, face, bary = rasterize_uv(np.asarray(frames.visual.uv), frames.faces, size)
    normals = np.asarray(frames.vertex_normals, dtype=np.float64)
    corners = np.asarray(frames.faces, dtype=np.int64)[face]
    normal = np.einsum("nk,nkc->nc", bary.astype(np.float64), normals[corners])
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-12)
    return texel, face, bary, normal


def _point_uv(mesh, face: np.ndarray, bary: np.ndarray) -> np.ndarray:
    """The UV (N, 2) of surface points (``face``, ``bary``) of ``mesh``, wrapped into
    [0, 1) (textures repeat)."""
    uv = np.asarray(mesh.visual.uv, dtype=np.float64)
    point_uv = np.einsum("nk,nkc->nc", bary, uv[np.asarray(mesh.faces, dtype=np.int64)[face]])
    return point_uv - np.floor(point_uv)


def _registered_map(example, kind: str, found: np.ndarray | None, size: int, query_normal):
    """A registered example's map of ``kind`` in the query's atlas at ``size``
    ((T, T) grey, or (T, T, 3) world normals onto the query's surface), read at its
    correspondence; its neutral value (a flat normal: the query's own) where it has none."""
    texel, face, bary = example.correspondence
    face = face.astype(np.int64)
    bary = bary.astype(np.float64)
    mesh = _example_mesh(example)
    covered = np.zeros((size, size), dtype=bool)
    covered.flat[texel] = True
    if kind != "normal":
        out = np.full((size, size), NEUTRAL[kind][0], dtype=np.float32)
        if found is not None:
            out.flat[texel] = sample_image(found[..., None], _point_uv(mesh, face, bary))[:, 0]
        return fill_background(out, covered)
    here = query_normal.reshape(-1, 3)[texel]
    if found is None:
        world = here
    else:
        uv = np.asarray(mesh.visual.uv, dtype=np.float64)
        faces = np.asarray(mesh.faces, dtype=np.int64)
        normals = np.asarray(mesh.vertex_normals, dtype=np.float64)
        local = decode_normals(sample_image(found, _point_uv(mesh, face, bary))).astype(np.float64)
        t, b, n = tangent_frames(corner_tangents(mesh.vertices, faces, normals, uv), normals,
                                 faces, face, bary)  # fmt: skip
        vectors = local[:, :1] * t + local[:, 1:2] * b + local[:, 2:] * n
        # Into the query's world by the registration (rotation, scale, a reflection), then
        # onto the query's surface: what the deformation and the fit leave is not relief.
        linear = np.asarray(example.registration.matrix, dtype=np.float64)[:3, :3]
        vectors, n = vectors @ linear.T, n @ linear.T
        vectors /= np.maximum(np.linalg.norm(vectors, axis=1, keepdims=True), 1e-12)
        n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
        world = _rotate_onto(vectors, n, here)
    out = query_normal.astype(np.float32, copy=True)
    out.reshape(-1, 3)[texel] = world
    return out


def atlas_maps(result, examples: list, frames) -> dict[str, np.ndarray]:
    """The examples' PBR maps in the query's atlas, each texel read where its colour was.

    Parameters
    ----------
    result : ColorizeResult
        Of :func:`imagemap.mesh.uvspace.colorize_uv`: ``source`` (T, T, 3) gives every
        texel's example and texel (in the example's own texture on the uv-space path, in
        its resampled texture, the query's atlas, on the registered path), ``mask`` the
        used texels.
    examples : list of UVExample
        In ``result.example_names`` order (:attr:`~imagemap.mesh.colorize.MeshResult.examples`);
        registered examples carry their correspondence.
    frames : trimesh.Trimesh
        The mesh as written (UVs, vertex normals; :func:`imagemap.scene.surface.frame_mesh`):
        the normal map is in the frames of its MikkTSpace tangents.

    Returns
    -------
    dict
        ``{kind: (T, T) or (T, T, 3) float32}`` for every kind of :data:`ATLAS_KINDS` at
        least one example has (none: empty); an example without a kind gives its neutral
        value; texels outside ``mask`` hold the nearest used texel's value (as the colour).
    """
    have = [_material_maps(getattr(_example_mesh(e).visual, "material", None)) for e in examples]
    kinds = [k for k in ATLAS_KINDS if any(k in m for m in have)]
    if not kinds:
        return {}
    source = np.asarray(result.source)
    mask = np.asarray(result.mask, dtype=bool)
    size = source.shape[0]
    index = np.clip(source[..., 0], 0, len(examples) - 1)
    rows, cols = source[..., 1], source[..., 2]
    registered = all(getattr(e, "correspondence", None) is not None for e in examples)
    query = _query_texels(frames, size) if registered and "normal" in kinds else None
    query_normal = None
    if query is not None:
        query_normal = np.zeros((size, size, 3), dtype=np.float32)
        query_normal[..., 2] = 1.0
        query_normal.reshape(-1, 3)[query[0]] = query[3]
        known = np.zeros((size, size), dtype=bool)
        known.flat[query[0]] = True
        query_normal = fill_background(query_normal, known)
    out: dict[str, np.ndarray] = {}
    for kind in kinds:
        channels = MAP_KINDS[kind]
        carried = np.empty((size, size, channels), dtype=np.float32)
        for k, (example, maps) in enumerate(zip(examples, have, strict=True)):
            here = index == k
            if not here.any():
                continue
            found = maps.get(kind)
            if registered:
                picture = _registered_map(example, kind, found, size, query_normal)
                ys, xs = np.clip(rows[here], 0, size - 1), np.clip(cols[here], 0, size - 1)
            elif found is None:
                carried[here] = NEUTRAL[kind]
                continue
            else:
                # The uv-space source is in the example's own texture; its maps may be of
                # another size: the same place, scaled.
                picture = found
                height, width = np.asarray(example.texture).shape[:2]
                ys = np.clip(((rows[here] + 0.5) * found.shape[0] / height).astype(np.int64),
                             0, found.shape[0] - 1)  # fmt: skip
                xs = np.clip(((cols[here] + 0.5) * found.shape[1] / width).astype(np.int64),
                             0, found.shape[1] - 1)  # fmt: skip
            carried[here] = picture[ys, xs].reshape(-1, channels)
        if kind == "normal" and registered and query is not None:
            texel, face, bary, _ = query
            world = carried.reshape(-1, 3)[texel].astype(np.float64)
            local = _to_tangent_space(world, frames, face, bary)
            flat = np.zeros((size, size, 3), dtype=np.float32)
            flat[..., 2] = 1.0
            flat.reshape(-1, 3)[texel] = local
            carried = encode_normals(flat)
        elif kind == "normal":
            carried = encode_normals(decode_normals(carried))
        carried = fill_background(carried, mask) if mask.any() else carried
        out[kind] = carried if channels == 3 else carried[..., 0]
    return out
