"""Mesh files: reading any mesh trimesh loads, and writing textured GLB and OBJ."""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

import numpy as np

from imagemap.io import InputError, atomic_path
from imagemap.mesh.views import texture_image

__all__ = [
    "MESH_SUFFIXES",
    "TEXTURED_SUFFIXES",
    "check_textured",
    "export_textured",
    "file_digest",
    "is_mesh_path",
    "load_mesh",
    "textured_mesh",
]

#: Suffixes read as meshes (anything trimesh loads that holds triangles).
MESH_SUFFIXES = (".obj", ".ply", ".glb", ".gltf", ".stl", ".off")
#: Suffixes written as textured meshes.
TEXTURED_SUFFIXES = (".glb", ".obj")
#: Bumped whenever rendering changes, so cached renders of examples are redone.


def is_mesh_path(path: str | os.PathLike) -> bool:
    return Path(path).suffix.lower() in MESH_SUFFIXES


def load_mesh(path: str | os.PathLike):
    """Read a mesh as one ``trimesh.Trimesh`` (a scene's geometries concatenated).

    Raises
    ------
    InputError
        Missing file, unknown format, unreadable, or no triangles.
    """
    import trimesh

    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: mesh file not found")
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise InputError(
            f"{path}: unsupported mesh format {path.suffix!r} (use {', '.join(MESH_SUFFIXES)})"
        )
    try:
        loaded = trimesh.load(path, force="mesh")
    except Exception as exc:  # any decoder failure is the file's fault here
        raise InputError(f"{path}: cannot be read as a mesh ({exc})") from exc
    if not isinstance(loaded, trimesh.Trimesh) or len(loaded.faces) == 0:
        raise InputError(f"{path}: holds no triangles")
    if not np.all(np.isfinite(loaded.vertices)):
        raise InputError(f"{path}: vertices have NaN or infinite coordinates")
    if np.ptp(loaded.vertices, axis=0).max() <= 0:
        raise InputError(f"{path}: all vertices coincide")
    return loaded


def file_digest(path: str | os.PathLike) -> str:
    """SHA-256 of a file's content (hex)."""
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def _pil(image: np.ndarray):
    from PIL import Image

    array = np.round(np.clip(np.nan_to_num(image[..., :3]), 0, 1) * 255).astype(np.uint8)
    return Image.fromarray(array, mode="RGB")


def textured_mesh(vertices: np.ndarray, faces: np.ndarray, uv: np.ndarray, image: np.ndarray):
    """A ``trimesh.Trimesh`` with per-vertex ``uv`` and ``image`` (H, W, 3) as its texture."""
    import trimesh
    from trimesh.visual.material import SimpleMaterial

    material = SimpleMaterial(image=_pil(image), diffuse=[255, 255, 255, 255])
    visual = trimesh.visual.TextureVisuals(uv=np.asarray(uv, dtype=np.float64), material=material)
    return trimesh.Trimesh(
        np.asarray(vertices, dtype=np.float64), np.asarray(faces), visual=visual, process=False
    )


def export_textured(mesh, path: str | os.PathLike) -> list[Path]:
    """Write a textured mesh as ``.glb`` (one file) or ``.obj`` + ``.mtl`` + ``.png``.

    Every file is written atomically; for OBJ the ``.obj`` is written last, so its
    presence means the set is complete. Returns the paths written.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".glb":
        data = mesh.export(file_type="glb")
        with atomic_path(path) as tmp:
            tmp.write_bytes(data)
        return [path]
    if suffix == ".obj":
        from trimesh.exchange.obj import export_obj

        mesh = mesh.copy()
        material = getattr(mesh.visual, "material", None)
        if material is not None:
            material.name = path.stem  # the texture is then STEM.png, not material_0.png
        text, files = export_obj(
            mesh, include_texture=True, return_texture=True, mtl_name=f"{path.stem}.mtl"
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
    raise InputError(f"{path}: a textured mesh is written as .glb or .obj")


def check_textured(path: str | os.PathLike) -> bool:
    """True when ``path`` loads back as a mesh with UVs and a texture image."""
    try:
        mesh = load_mesh(path)
    except InputError:
        return False
    return getattr(mesh.visual, "uv", None) is not None and texture_image(mesh) is not None
