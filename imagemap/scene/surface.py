"""What the artist set on a mesh, kept on the mesh textured anew (issue #34).

:func:`keep_surface` carries the input's normals (or crease-aware smooth normals),
the alpha of its base colour and its material's alpha mode, cut-off and sides onto
the textured result of :func:`~imagemap.scene.bake.bake_views` or
:func:`~imagemap.scene.bake.project_texture` (same faces, same order).
"""

from __future__ import annotations

import numpy as np

from imagemap.core.blend import fill_background
from imagemap.scene.bake import rasterize_uv
from imagemap.scene.files import (
    SurfaceMaterial,
    _base_colour_texture,
    _material_maps,
    _split_by_normals,
    corner_normals,
    material_of,
    texture_alpha,
    textured_mesh,
)
from imagemap.scene.views import sample_image

__all__ = ["frame_mesh", "keep_surface", "kept_geometry"]


def keep_surface(textured, source, *, material: SurfaceMaterial | None = None):
    """``textured`` with what the artist set on ``source`` kept.

    ``textured`` is ``source`` textured anew (the same faces in the same order, as
    :func:`~imagemap.scene.bake.bake_views` and
    :func:`~imagemap.scene.bake.project_texture` make it). Kept, face by face:

    - the normals: ``source``'s own where its file had them, else smooth normals
      with creases over :data:`CREASE_DEGREES` (vertices split where corners differ);
    - the alpha of ``source``'s base colour (its texture's alpha sampled at the same
      surface points, times its factor), into the new texture's alpha channel;
    - ``alphaMode``, ``alphaCutoff``, ``doubleSided``, stated factors and the
      material's name (:func:`material_of`), unless ``material`` is given;
    - ``source``'s roughness, metallic and ao maps (sampled at the same surface
      points) for each kind ``textured`` has no map of.

    Maps already on ``textured`` (normal, roughness, metallic, ao) stay: the examples'
    maps win over the input's.

    Examples
    --------
    >>> import trimesh
    >>> box = trimesh.creation.box()
    >>> from imagemap.scene.files import textured_mesh
    >>> plain = textured_mesh(box.vertices, box.faces, box.vertices[:, :2] + 0.5,
    ...                       np.full((4, 4, 3), 0.5))
    >>> kept = keep_surface(plain, box)
    >>> len(kept.vertices), bool(np.allclose(kept.vertex_normals[kept.faces],
    ...                                       box.face_normals[:, None, :]))
    (24, True)
    """
    settings = material if material is not None else material_of(source)
    vertices, new_faces, uv, normals = kept_geometry(textured, source)
    same = len(source.faces) == len(new_faces)
    image = _base_colour_texture(textured, "keep_surface: textured")
    alpha = _carried_alpha(textured, source, image.shape[:2]) if same else None
    if alpha is None:
        _, factor = texture_alpha(source)
        alpha = None if factor >= 1.0 else np.full(image.shape[:2], factor, np.float32)
    if alpha is not None:
        image = np.concatenate([image, alpha[..., None]], axis=2)
    maps = _material_maps(textured.visual.material)
    if same:
        # The input's own roughness, metallic and ao maps where the examples gave none
        # (the input's factor alone would flatten a textured roughness to one value).
        for kind, values in _source_grey_maps(source).items():
            if kind not in maps:
                carried = _carried(textured, source, values, image.shape[:2])
                if carried is not None:
                    maps[kind] = carried
    return textured_mesh(
        vertices,
        new_faces,
        uv,
        image,
        normals=normals,
        maps=maps,
        material=settings,
    )


def kept_geometry(textured, source) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The vertices, faces, UVs and normals :func:`keep_surface` gives ``textured``.

    The normals are ``source``'s own where its file had them, else smooth with creases
    (:func:`~imagemap.scene.files.corner_normals`); vertices are split where a
    vertex's corners disagree. Faces stay in their order.
    """
    vertices = np.asarray(textured.vertices, dtype=np.float64)
    faces = np.asarray(textured.faces, dtype=np.int64)
    uv = np.asarray(textured.visual.uv, dtype=np.float64)
    same = len(source.faces) == len(faces)
    if same and source.metadata.get("file_normals") and "vertex_normals" in source._cache:
        corners = np.asarray(source.vertex_normals, dtype=np.float64)[source.faces]
    elif same:
        corners = corner_normals(source.vertices, source.faces)
    else:
        corners = corner_normals(vertices, faces)
    new_faces, origin = _split_by_normals(faces, corners)
    normals = np.zeros((len(origin), 3))
    normals[new_faces.ravel()] = corners.reshape(-1, 3)
    return vertices[origin], new_faces, uv[origin], normals


def frame_mesh(textured, source):
    """A mesh of :func:`kept_geometry` (UVs and vertex normals as written): the
    frames a normal map is baked in (``textured``'s texture is not carried)."""
    import trimesh  # deferred: start-up (trimesh)

    vertices, faces, uv, normals = kept_geometry(textured, source)
    mesh = trimesh.Trimesh(
        vertices, faces, visual=trimesh.visual.TextureVisuals(uv=uv), process=False
    )
    mesh.vertex_normals = normals  # type: ignore[method-assign]
    return mesh


def _carried_alpha(textured, source, shape: tuple[int, int]) -> np.ndarray | None:
    """``source``'s base colour alpha at every texel of ``textured``'s texture (same faces)."""
    alpha, factor = texture_alpha(source)
    if alpha is None:
        return None
    return _carried(textured, source, alpha * np.float32(factor), shape)


def _source_grey_maps(source) -> dict[str, np.ndarray]:
    """The grey PBR maps of ``source``'s material as the values it renders with (the
    packed texture's channel times its factor), by kind: roughness, metallic, ao."""
    material = getattr(getattr(source, "visual", None), "material", None)
    maps: dict[str, np.ndarray] = {}
    packed = getattr(material, "metallicRoughnessTexture", None)
    if packed is not None:
        packed = np.asarray(packed.convert("RGB"), np.float32) / 255.0
        for channel, kind, factor in (
            (1, "roughness", getattr(material, "roughnessFactor", None)),
            (2, "metallic", getattr(material, "metallicFactor", None)),
        ):
            # glTF: the value is the channel times the factor (1 when not stated).
            maps[kind] = packed[..., channel] * np.float32(1.0 if factor is None else factor)
    occlusion = getattr(material, "occlusionTexture", None)
    if occlusion is not None:
        maps["ao"] = np.asarray(occlusion.convert("L"), np.float32) / 255.0
    return maps


def _carried(textured, source, values: np.ndarray, shape: tuple[int, int]) -> np.ndarray | None:
    """A grey map of ``source`` (in its UV layout) at every texel of ``textured``'s
    texture of ``shape`` (same faces); None when ``source`` has no UVs."""
    source_uv = getattr(source.visual, "uv", None)
    if source_uv is None:
        return None
    height, width = shape
    size = max(height, width)
    texel, face, bary = rasterize_uv(np.asarray(textured.visual.uv), textured.faces, size)
    corner_uv = np.asarray(source_uv, dtype=np.float64)[np.asarray(source.faces)[face]]
    point_uv = np.einsum("nk,nkc->nc", bary, corner_uv)
    point_uv -= np.floor(point_uv)  # textures repeat
    out = np.ones((size, size), dtype=np.float32)
    out.flat[texel] = sample_image(np.asarray(values, np.float32)[..., None], point_uv)[:, 0]
    covered = np.zeros((size, size), dtype=bool)
    covered.flat[texel] = True
    out = fill_background(out, covered)
    if (height, width) != (size, size):
        from skimage.transform import (
            resize,
        )  # deferred: start-up: skimage.transform (0.4 s) only for a resized texture

        out = resize(out, (height, width), order=1, anti_aliasing=False)
    return out.astype(np.float32)
