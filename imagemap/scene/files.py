"""Mesh files: reading any mesh trimesh loads, and writing textured GLB and OBJ.

What a written mesh carries so that it imports as intended (issue #34):

- **A dielectric material by default**: glTF's ``metallicFactor`` defaults to 1.0, so
  a material without it imports as metal (Blender: Metallic 1.0, skin renders
  bronze). Every material written here states ``metallicFactor`` (0 unless the input
  or a metallic map says otherwise) and ``roughnessFactor``.
- **Vertex normals**: the input's own where it has them (carried face by face), else
  smooth normals over the faces that meet at a point at less than
  :data:`CREASE_DEGREES`, so a UV seam shows no crease and a box keeps its edges.
- **The input material's** ``alphaMode``, ``alphaCutoff``, ``doubleSided`` and the alpha
  of its base colour (texture alpha sampled at the same surface points), so
  alpha-masked fins stay fins (:func:`imagemap.scene.surface.keep_surface`).
- **Units**: glTF is in metres; coordinates are written as the source has them
  unless a scale is given (:data:`UNIT_SCALES`), and the size is stated.
- **PBR maps** beside the colour: ``normal`` (tangent space, OpenGL +Y), and
  ``roughness``, ``metallic``, ``ao`` packed as glTF wants them
  (``metallicRoughnessTexture``: G roughness, B metallic; ``occlusionTexture``: R).
"""

from __future__ import annotations

import hashlib
import os
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from imagemap.io import InputError, atomic_path
from imagemap.outputs import (  # one list each: the overwrite rule and the CLI read them too
    MESH_SUFFIXES,
    TEXTURED_SUFFIXES,
)
from imagemap.scene.views import texture_image
from imagemap.validate import check_mesh

__all__ = [
    "CREASE_DEGREES",
    "DEFAULT_ROUGHNESS",
    "MESH_SUFFIXES",
    "TEXTURED_SUFFIXES",
    "UNIT_SCALES",
    "SurfaceMaterial",
    "check_finite",
    "check_textured",
    "corner_normals",
    "export_textured",
    "file_digest",
    "is_mesh_path",
    "load_mesh",
    "material_of",
    "textured_mesh",
    "texture_alpha",
    "unit_scale",
]

#: Roughness written when neither the input nor a roughness map gives one: a matte
#: dielectric (skin, scales, painted wood are 0.4-0.8 in the usual PBR charts); the
#: old export's 0.904 came from trimesh's glossiness conversion, not from a choice.
DEFAULT_ROUGHNESS = 0.6
#: Faces meeting at a point at more than this angle keep their own normals there
#: (a crease); below it the normals are averaged (smooth). 60 degrees keeps a box's
#: edges and smooths the generated fish (icosphere-based parts, at most 24 degrees
#: between neighbouring faces away from where fins meet the body).
CREASE_DEGREES = 60.0
#: Metres per unit of each ``--units`` name (glTF is in metres).
UNIT_SCALES = {"m": 1.0, "cm": 0.01, "mm": 0.001, "in": 0.0254, "ft": 0.3048}


def is_mesh_path(path: str | os.PathLike) -> bool:
    return Path(path).suffix.lower() in MESH_SUFFIXES


def load_mesh(path: str | os.PathLike):
    """Read a mesh as one ``trimesh.Trimesh`` (a scene's geometries concatenated).

    The file is read as it is, checked, and only then processed (trimesh's merging of
    duplicate vertices): processing drops the faces of a non-finite vertex without a
    word, which would hide a damaged file.

    Raises
    ------
    InputError
        Missing file, unknown format, unreadable, no triangles, vertices or UV
        coordinates that are NaN or infinite (how many, and how many faces they touch),
        all vertices at one point, or faces without area (every vertex on one line).
    """
    import trimesh  # deferred: start-up (trimesh)

    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: mesh file not found")
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise InputError(
            f"{path}: unsupported mesh format {path.suffix!r} (use {', '.join(MESH_SUFFIXES)})"
        )
    try:
        loaded = trimesh.load(path, force="mesh", process=False)
    except Exception as exc:  # any decoder failure is the file's fault here
        raise InputError(f"{path}: cannot be read as a mesh ({exc})") from exc
    if not isinstance(loaded, trimesh.Trimesh) or len(loaded.faces) == 0:
        raise InputError(f"{path}: holds no triangles")
    check_finite(loaded, str(path))
    try:
        loaded.process()  # what trimesh.load does by default: duplicate vertices merged
        normals = _file_normals(path, loaded)
    except Exception as exc:
        raise InputError(f"{path}: cannot be read as a mesh ({exc})") from exc
    if normals is not None:
        # trimesh's cache_decorator is a property with a setter, which mypy reads as a method
        loaded.vertex_normals = normals  # type: ignore[method-assign]
    loaded.metadata["file_normals"] = normals is not None
    if not np.all(np.isfinite(loaded.vertices)):
        raise InputError(f"{path}: vertices have NaN or infinite coordinates")
    if np.ptp(loaded.vertices, axis=0).max() <= 0:
        raise InputError(f"{path}: all vertices coincide")
    if not np.asarray(loaded.area_faces).sum() > 0:
        raise InputError(
            f"{path}: its {len(loaded.faces)} faces have no area (every vertex on one line): "
            "no surface to see or texture"
        )
    return loaded


def check_finite(mesh, what: str = "mesh") -> None:
    """InputError naming ``what`` (a file, an argument) when the mesh's vertices or UV
    coordinates are NaN or infinite: how many, and how many faces they touch (trimesh's
    processing would drop those faces without a word; they are refused instead).

    Examples
    --------
    >>> import trimesh
    >>> box = trimesh.creation.box()
    >>> box.vertices[2] = np.nan
    >>> check_finite(box, "box.ply")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    imagemap.errors.InputError: box.ply: 1 of 8 vertices are NaN or infinite (the first: ...
    """
    faces = np.asarray(mesh.faces, dtype=np.int64)
    uv = getattr(getattr(mesh, "visual", None), "uv", None)
    for label, values in (("vertices", mesh.vertices), ("UV coordinates", uv)):
        if values is None or len(values) != len(mesh.vertices):
            continue
        bad = ~np.all(np.isfinite(np.asarray(values, dtype=np.float64)), axis=1)
        if bad.any():
            touched = int(bad[faces].any(axis=1).sum())
            raise InputError(
                f"{what}: {int(bad.sum())} of {len(bad)} {label} are NaN or infinite "
                f"(the first: vertex {int(np.argmax(bad))}), touching {touched} of "
                f"{len(faces)} faces: the file is damaged; repair or export it again "
                "(nothing is dropped silently)"
            )


def _file_normals(path: Path, loaded) -> np.ndarray | None:
    """The file's own vertex normals (glTF NORMAL, OBJ vn, PLY nx ny nz), as loaded.

    ``trimesh.load(force="mesh")`` drops them when it flattens a scene; this
    reads the file again and concatenates the normals in the same order, each
    geometry's transformed like its vertices (None when a geometry has none or the
    vertex counts do not agree).
    """
    import trimesh  # deferred: start-up (trimesh)

    scene = trimesh.load(path)
    if isinstance(scene, trimesh.Trimesh):
        scene = trimesh.Scene(scene)
    if not isinstance(scene, trimesh.Scene):
        return None  # a point cloud: no normals (load_mesh finds it holds no triangles)
    parts = []
    for node in scene.graph.nodes_geometry:
        transform, name = scene.graph[node]
        geometry = scene.geometry[name]
        if not isinstance(geometry, trimesh.Trimesh) or "vertex_normals" not in geometry._cache:
            return None
        linear = np.asarray(transform, dtype=np.float64)[:3, :3]
        normals = np.asarray(geometry.vertex_normals, dtype=np.float64) @ np.linalg.inv(linear)
        parts.append(normals / np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12))
    if not parts:
        return None
    normals = np.concatenate(parts)
    return normals if len(normals) == len(loaded.vertices) else None


def file_digest(path: str | os.PathLike) -> str:
    """SHA-256 of a file's content (hex)."""
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def _pil(image: np.ndarray):
    """RGB, RGBA or grey (H, W[, C]) in [0, 1] -> an 8-bit PIL image of the same bands."""
    from PIL import Image  # deferred: start-up: Pillow only where a texture is written

    image = np.asarray(image)
    if image.ndim == 3 and image.shape[2] == 1:
        image = image[..., 0]
    if image.ndim == 3 and image.shape[2] not in (3, 4):
        image = image[..., :3]
    array = np.round(np.clip(np.nan_to_num(image), 0, 1) * 255).astype(np.uint8)
    mode = {2: "L", 3: "RGB"}[array.ndim] if array.ndim == 2 or array.shape[2] == 3 else "RGBA"
    return Image.fromarray(array, mode=mode)


@dataclass(frozen=True)
class SurfaceMaterial:
    """The material settings a written mesh states (glTF names in brackets).

    Attributes
    ----------
    metallic : float
        ``metallicFactor``; 0 (a dielectric) unless the input says otherwise.
    roughness : float
        ``roughnessFactor``.
    alpha_mode : str
        ``alphaMode``: ``"OPAQUE"``, ``"MASK"`` or ``"BLEND"``.
    alpha_cutoff : float
        ``alphaCutoff`` (used with ``"MASK"``).
    double_sided : bool
        ``doubleSided``.
    name : str or None
        The material's ``name`` (an engine's material slots and overrides find it by
        name); None: unnamed.
    """

    metallic: float = 0.0
    roughness: float = DEFAULT_ROUGHNESS
    alpha_mode: str = "OPAQUE"
    alpha_cutoff: float = 0.5
    double_sided: bool = False
    name: str | None = None


def material_of(mesh) -> SurfaceMaterial:
    """The material settings of a loaded mesh: what it states, defaults for the rest.

    Examples
    --------
    >>> import trimesh
    >>> material_of(trimesh.creation.box())  # no material: a matte dielectric
    SurfaceMaterial(metallic=0.0, roughness=0.6, alpha_mode='OPAQUE', alpha_cutoff=0.5, double_sided=False, name=None)
    """  # noqa: E501
    material = getattr(getattr(mesh, "visual", None), "material", None)
    settings = SurfaceMaterial()
    name = getattr(material, "name", None)
    if isinstance(name, str) and name:
        settings = replace(settings, name=name)
    if material is None or not hasattr(material, "metallicFactor"):
        return settings  # no material, or an OBJ's (no metallic, no alpha mode)
    changes: dict[str, Any] = {}  # SurfaceMaterial's fields: floats, a str and a bool
    if material.metallicFactor is not None:
        changes["metallic"] = float(np.clip(material.metallicFactor, 0.0, 1.0))
    if material.roughnessFactor is not None:
        changes["roughness"] = float(np.clip(material.roughnessFactor, 0.0, 1.0))
    if isinstance(material.alphaMode, str) and material.alphaMode.upper() in ("MASK", "BLEND"):
        changes["alpha_mode"] = material.alphaMode.upper()
    if material.alphaCutoff is not None:
        changes["alpha_cutoff"] = float(material.alphaCutoff)
    if material.doubleSided is not None:
        changes["double_sided"] = bool(material.doubleSided)
    return replace(settings, **changes)


def texture_alpha(mesh) -> tuple[np.ndarray | None, float]:
    """(alpha of the base colour texture (H, W) or None, the base colour factor's alpha)."""
    material = getattr(getattr(mesh, "visual", None), "material", None)
    factor = 1.0
    image = None
    if material is not None:
        colour = getattr(material, "baseColorFactor", None)
        if colour is not None:
            colour = np.asarray(colour, dtype=np.float64).ravel()
            factor = float(colour[3] / 255.0 if colour.max() > 1.0 else colour[3])
        image = getattr(material, "baseColorTexture", None)
        if image is None:
            image = getattr(material, "image", None)
    if image is None or "A" not in image.getbands():
        return None, factor
    return np.asarray(image.getchannel("A"), dtype=np.float32) / 255.0, factor


def _base_colour_texture(mesh, what: str) -> np.ndarray:
    """``mesh``'s base colour texture (:func:`texture_image`); InputError naming ``what``
    when it has none (a mesh meant to be textured that is not)."""
    image = texture_image(mesh)
    if image is None:
        raise InputError(f"{what}: the mesh has no base colour texture")
    return image


def _face_normals(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit face normals (F, 3) and areas (F,) (degenerate faces: zero normal, zero area)."""
    corners = vertices[faces]
    cross = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    length = np.linalg.norm(cross, axis=1)
    return cross / np.maximum(length, 1e-300)[:, None], 0.5 * length


def corner_normals(
    vertices: np.ndarray, faces: np.ndarray, *, crease_degrees: float = CREASE_DEGREES
) -> np.ndarray:
    """Smooth normals per face corner (F, 3, 3), kept apart across creases.

    A corner's normal is the area-weighted mean of the normals of every face that
    touches the same point (vertices at one position count as one, so UV seams
    do not show) and meets the corner's face at less than ``crease_degrees``.

    Examples
    --------
    >>> import trimesh
    >>> box = trimesh.creation.box()
    >>> normals = corner_normals(box.vertices, box.faces)
    >>> bool(np.allclose(normals, box.face_normals[:, None, :]))  # a box keeps its edges
    True
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    face_normal, area = _face_normals(vertices, faces)
    # One id per position: vertices split along UV seams are one point here.
    scale = max(float(np.ptp(vertices, axis=0).max()), 1e-300)
    _, point = np.unique(np.round(vertices / scale * 1e9), axis=0, return_inverse=True)
    corner_point = point.ravel()[faces.ravel()]  # (3F,)
    corner_face = np.repeat(np.arange(len(faces)), 3)
    order = np.argsort(corner_point, kind="stable")
    sorted_point = corner_point[order]
    starts = np.r_[0, np.flatnonzero(np.diff(sorted_point)) + 1]
    sizes = np.diff(np.r_[starts, len(order)])
    group_of = np.repeat(np.arange(len(starts)), sizes)  # group of each sorted corner
    # Every (corner, neighbour corner at the same point) pair: sum of sizes^2 pairs.
    reps = sizes[group_of]
    first = np.repeat(np.arange(len(order)), reps)
    offset = np.arange(reps.sum()) - np.repeat(np.cumsum(reps) - reps, reps)
    second = starts[group_of[first]] + offset
    mine, theirs = corner_face[order[first]], corner_face[order[second]]
    agree = np.einsum("ij,ij->i", face_normal[mine], face_normal[theirs])
    keep = agree >= np.cos(np.radians(crease_degrees)) - 1e-9
    weighted = face_normal[theirs[keep]] * area[theirs[keep], None]
    total = np.zeros((len(order), 3))
    np.add.at(total, first[keep], weighted)
    normals = np.empty_like(total)
    normals[order] = total
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    fallback = face_normal[corner_face]
    normals = np.where(length > 1e-300, normals / np.maximum(length, 1e-300), fallback)
    return normals.reshape(-1, 3, 3)


def _split_by_normals(faces: np.ndarray, normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(new faces, source vertex of each new vertex) with one vertex per distinct
    (vertex, corner normal): a vertex whose corners disagree is split."""
    faces = np.asarray(faces, dtype=np.int64)
    key = np.column_stack([faces.ravel(), np.round(normals.reshape(-1, 3) * 1e5)])
    unique, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    return inverse.reshape(-1, 3), unique[:, 0].astype(np.int64)


def _smooth_vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Per-vertex normals, smooth across UV seams (no crease kept, no vertex split)."""
    normals = corner_normals(vertices, faces, crease_degrees=180.0).reshape(-1, 3)
    out = np.zeros((len(vertices), 3))
    out[np.asarray(faces, dtype=np.int64).ravel()] = normals  # all corners of a point agree
    length = np.linalg.norm(out, axis=1, keepdims=True)
    return np.where(length > 0, out / np.maximum(length, 1e-300), [0.0, 0.0, 1.0])


def textured_mesh(
    vertices: np.ndarray,
    faces: np.ndarray,
    uv: np.ndarray,
    image: np.ndarray,
    *,
    normals: np.ndarray | None = None,
    maps: dict[str, np.ndarray] | None = None,
    material: SurfaceMaterial | None = None,
):
    """A ``trimesh.Trimesh`` with per-vertex ``uv``, ``image`` as its texture and a
    glTF material that states every factor (see the module notes).

    Parameters
    ----------
    vertices, faces, uv : arrays (V, 3), (F, 3), (V, 2)
    image : ndarray, (H, W, 3) or (H, W, 4)
        The base colour in [0, 1] (with alpha when 4 channels).
    normals : ndarray, (V, 3), optional
        Vertex normals; smooth normals (across UV seams) when not given.
    maps : dict, optional
        PBR maps in the texture's layout, in [0, 1]: ``"normal"`` (H, W, 3) tangent
        space, ``"roughness"``, ``"metallic"``, ``"ao"`` (H, W).
    material : SurfaceMaterial, optional
        Factors and alpha settings (a matte dielectric by default).

    Examples
    --------
    >>> import trimesh
    >>> box = trimesh.creation.box()
    >>> mesh = textured_mesh(box.vertices, box.faces, box.vertices[:, :2] + 0.5,
    ...                      np.full((4, 4, 3), 0.5), maps={"roughness": np.full((4, 4), 0.3)})
    >>> mesh.visual.material.metallicFactor, mesh.visual.material.roughnessFactor
    (0.0, 1.0)
    """
    import trimesh  # deferred: start-up (trimesh)
    from trimesh.visual.material import PBRMaterial  # deferred: start-up (trimesh)

    material = material or SurfaceMaterial()
    maps = dict(maps or {})
    unknown = set(maps) - {"normal", "roughness", "metallic", "ao"}
    if unknown:
        raise InputError(f"textured_mesh: unknown map(s) {sorted(unknown)}")
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces)
    fields = {
        "baseColorTexture": _pil(image),
        "baseColorFactor": [1.0, 1.0, 1.0, 1.0],
        "metallicFactor": 1.0 if "metallic" in maps else float(material.metallic),
        "roughnessFactor": 1.0 if "roughness" in maps else float(material.roughness),
        "alphaMode": material.alpha_mode,
        "doubleSided": bool(material.double_sided),
    }
    if material.name:
        fields["name"] = material.name
    if material.alpha_mode == "MASK":
        fields["alphaCutoff"] = float(material.alpha_cutoff)
    if "normal" in maps:
        fields["normalTexture"] = _pil(maps["normal"])
    if "roughness" in maps or "metallic" in maps:
        shape = np.asarray(maps.get("roughness", maps.get("metallic"))).shape[:2]
        packed = np.ones(shape + (3,), dtype=np.float32)  # R unused, G rough, B metal
        for channel, kind in ((1, "roughness"), (2, "metallic")):
            if kind in maps:
                packed[..., channel] = np.asarray(maps[kind], dtype=np.float32).reshape(shape)
        fields["metallicRoughnessTexture"] = _pil(packed)
    if "ao" in maps:
        fields["occlusionTexture"] = _pil(maps["ao"])
    visual = trimesh.visual.TextureVisuals(
        uv=np.asarray(uv, dtype=np.float64), material=PBRMaterial(**fields)
    )
    mesh = trimesh.Trimesh(vertices, faces, visual=visual, process=False)
    # trimesh's cache_decorator is a property with a setter, which mypy reads as a method
    mesh.vertex_normals = (  # type: ignore[method-assign]
        _smooth_vertex_normals(vertices, faces) if normals is None else np.asarray(normals)
    )
    return mesh


def _material_maps(material) -> dict[str, np.ndarray]:
    """The PBR maps a textured mesh's material carries, as arrays in [0, 1]."""
    maps = {}
    if getattr(material, "normalTexture", None) is not None:
        maps["normal"] = np.asarray(material.normalTexture.convert("RGB"), np.float32) / 255.0
    packed = getattr(material, "metallicRoughnessTexture", None)
    if packed is not None:
        packed = np.asarray(packed.convert("RGB"), np.float32) / 255.0
        if material.roughnessFactor == 1.0:
            maps["roughness"] = packed[..., 1]
        if material.metallicFactor == 1.0:
            maps["metallic"] = packed[..., 2]
    if getattr(material, "occlusionTexture", None) is not None:
        maps["ao"] = np.asarray(material.occlusionTexture.convert("L"), np.float32) / 255.0
    return maps


def unit_scale(units: str | None = None, scale: float | None = None) -> float:
    """Metres per source unit from ``--units`` or ``--scale`` (1: the source's as metres).

    Examples
    --------
    >>> unit_scale("mm"), unit_scale(scale=2.5), unit_scale()
    (0.001, 2.5, 1.0)
    """
    if units is not None and scale is not None:
        raise InputError("--units and --scale: give one of them (--units mm is --scale 0.001)")
    if units is not None:
        if units not in UNIT_SCALES:
            raise InputError(f"--units: {units!r} is not one of {', '.join(UNIT_SCALES)}")
        return UNIT_SCALES[units]
    if scale is not None:
        if not (np.isfinite(scale) and scale > 0):
            raise InputError(f"--scale: must be a positive number, got {scale}")
        return float(scale)
    return 1.0


#: The custom vertex attribute trimesh writes the tangents as, renamed ``TANGENT``.
_TANGENT = "_TANGENT"


def _with_tangents(mesh, normals: np.ndarray, uv: np.ndarray):
    """``mesh`` with glTF's TANGENT (MikkTSpace, the frames the route bakes normal maps
    in) as the custom attribute trimesh writes (renamed ``TANGENT`` on export), its
    vertices split where UV triangles of both orientations meet (two tangents)."""
    import trimesh  # deferred: start-up (trimesh)

    from imagemap.tangents import mikk_tangents, tangent_split  # deferred: start-up

    faces, origin = tangent_split(mesh.faces, uv)
    if len(origin) > len(mesh.vertices):
        visual = trimesh.visual.TextureVisuals(uv=uv[origin], material=mesh.visual.material)
        split = trimesh.Trimesh(
            np.asarray(mesh.vertices)[origin], faces, visual=visual, process=False
        )
        split.metadata.update(mesh.metadata)
        mesh = split
        normals = normals[origin]
        mesh.vertex_normals = normals
    tangents = mikk_tangents(mesh.vertices, mesh.faces, normals, uv[origin])
    mesh.vertex_attributes[_TANGENT] = tangents.astype(np.float32)
    return mesh


def export_textured(mesh, path: str | os.PathLike, *, scale: float = 1.0) -> list[Path]:
    """Write a textured mesh as ``.glb`` (one file) or ``.obj`` + ``.mtl`` + ``.png``.

    Every file is written atomically; for OBJ the ``.obj`` is written last, so its
    presence means the set is complete. Vertex normals are written (computed when
    the mesh has none); ``scale`` multiplies the coordinates (glTF is in metres:
    see :func:`unit_scale`) and is recorded in the GLB's ``asset.extras``. A GLB
    whose material has a normal texture gets a vertex ``TANGENT`` in the MikkTSpace
    convention (:func:`imagemap.tangents.mikk_tangents`), the frame the mesh
    route bakes normal maps in; OBJ has no slot for tangents (a viewer computes its own).
    Returns the paths written.
    """
    check_mesh(mesh, "export_textured: mesh", paths=False)  # None or a Scene: InputError
    path = Path(path)
    suffix = path.suffix.lower()
    scale = float(scale)
    if not (np.isfinite(scale) and scale > 0):
        raise InputError(f"{path}: scale must be a positive number, got {scale}")
    if suffix not in (".glb", ".obj"):
        raise InputError(f"{path}: a textured mesh is written as .glb or .obj")
    normals = np.asarray(mesh.vertex_normals)  # computed now if the mesh has none
    mesh = mesh.copy()
    if scale != 1.0:
        mesh.vertices = np.asarray(mesh.vertices) * scale
    mesh.vertex_normals = normals
    if suffix == ".glb":
        material = getattr(mesh.visual, "material", None)
        uv = getattr(mesh.visual, "uv", None)
        tangents = getattr(material, "normalTexture", None) is not None and uv is not None
        if tangents:
            mesh = _with_tangents(mesh, normals, np.asarray(uv))

        def stated(tree: dict) -> None:
            extras = tree.setdefault("asset", {}).setdefault("extras", {})
            extras["imagemap"] = {"scale_to_metres": scale, "generator": "imagemap"}
            for written in tree.get("meshes", []):
                for primitive in written.get("primitives", []):
                    attributes = primitive.get("attributes", {})
                    if _TANGENT in attributes:
                        attributes["TANGENT"] = attributes.pop(_TANGENT)

        data = mesh.export(file_type="glb", include_normals=True, tree_postprocessor=stated)
        with atomic_path(path) as tmp:
            tmp.write_bytes(data)
        return [path]
    from trimesh.exchange.obj import export_obj  # deferred: start-up (trimesh)

    material = getattr(mesh.visual, "material", None)
    if material is not None:
        material.name = path.stem  # the texture is then STEM.png, not material_0.png
    text, files = export_obj(
        mesh,
        include_normals=True,
        include_texture=True,
        return_texture=True,
        mtl_name=f"{path.stem}.mtl",
    )
    written = []
    # Texture first, then the .mtl, then the .obj: the .obj's presence means complete.
    for name, data in sorted(files.items(), key=lambda item: item[0].endswith(".mtl")):
        target = path.parent / name
        with atomic_path(target) as tmp:
            tmp.write_bytes(data)
        written.append(target)
    with atomic_path(path) as tmp:
        tmp.write_text(text)
    return [*written, path]


def check_textured(path: str | os.PathLike) -> bool:
    """True when ``path`` loads back as a mesh with UVs and a texture image."""
    try:
        mesh = load_mesh(path)
    except InputError:
        return False
    return getattr(mesh.visual, "uv", None) is not None and texture_image(mesh) is not None
