"""Textured meshes as database examples: rendered from a view on first use, cached on disk."""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

import numpy as np

from imagemap.cache import PACKAGE, source_digest
from imagemap.cache import cache_dir as library_cache_dir
from imagemap.example import Example
from imagemap.io import InputError, read_npz, write_npz
from imagemap.materials import NEUTRAL, atlas_normals_to_view
from imagemap.scene.files import _material_maps, file_digest, is_mesh_path, load_mesh
from imagemap.scene.views import (
    DEFAULT_MARGIN,
    DEFAULT_SIZE,
    FRONT,
    View,
    parse_view,
    render_colours,
    render_mesh,
    sample_image,
)

__all__ = ["RENDER_SOURCES", "MeshExample", "maps_seen", "mesh_examples", "render_digest"]

#: The modules (paths under ``imagemap/``) whose code decides a mesh example's render:
#: this one (the cache and the PBR maps seen, :func:`maps_seen`), the views and colours
#: (:mod:`~imagemap.scene.views`), the ray caster (:mod:`~imagemap.scene.raycast`), the
#: mesh's reading and its material's maps (:mod:`~imagemap.scene.files`), and the normal
#: map's frames (:mod:`imagemap.materials`, :mod:`imagemap.tangents`). The render cache is
#: keyed by their source (:func:`render_digest`): an edit to any renders the examples anew,
#: with no version number to remember (a test checks the list against the code a render
#: runs).
RENDER_SOURCES = (
    "cache.py",  # the key itself: a wrong one would reuse a stale render
    "scene/examples.py",
    "scene/views.py",
    "scene/raycast.py",
    "scene/files.py",
    "materials.py",
    "tangents.py",
)
#: The package folder the sources are read from.
_PACKAGE = PACKAGE


def render_digest() -> str:
    """A digest of :data:`RENDER_SOURCES`' source (the version where a file cannot be read,
    as in a frozen install), part of every cached render's key.

    Examples
    --------
    >>> len(render_digest())
    24
    """
    return source_digest(RENDER_SOURCES, _PACKAGE)[:24]


class MeshExample(Example):
    """An example whose depth and image-map are rendered from a textured mesh.

    Rendered on first use for its view and size, and cached on disk in
    ``cache_dir/meshes/`` under a key of the file's content hash, the view, the size,
    the margin and the rendering code (:func:`render_digest`): a changed file, view or
    renderer renders anew.
    """

    def __init__(
        self,
        name: str,
        mesh_path: Path,
        view: View = FRONT,
        size: tuple[int, int] = DEFAULT_SIZE,
        cache_dir: str | os.PathLike | None = None,
        margin: float = DEFAULT_MARGIN,
    ) -> None:
        super().__init__(name=name)
        self.mesh_path = Path(mesh_path)
        self.view = view
        self.size = (int(size[0]), int(size[1]))
        self.margin = margin
        self.cache_dir = Path(cache_dir) if cache_dir is not None else library_cache_dir()

    def at_view(self, view: View, size: tuple[int, int] | None = None) -> MeshExample:
        """The same mesh rendered from another view (and size)."""
        return MeshExample(
            self.name, self.mesh_path, view, size or self.size, self.cache_dir, self.margin
        )

    def cache_path(self) -> Path:
        digest = file_digest(self.mesh_path)
        key = f"{digest}|{self.view}|{self.size}|{self.margin}|{render_digest()}"
        short = hashlib.sha256(key.encode()).hexdigest()[:24]
        return self.cache_dir / "meshes" / f"{self.name}-{short}.npz"

    def _render(self) -> dict:
        if "depth" in self._arrays:  # (maps may be cached before the render)
            return self._arrays
        cached = self.cache_path()
        if cached.is_file():
            try:
                arrays = read_npz(cached, what="cached render")
                if {"depth", "image"} <= set(arrays):
                    self._arrays.update(arrays)
                    return self._arrays
            except InputError:
                pass  # a damaged cache entry is rendered anew
        mesh = load_mesh(self.mesh_path)
        render = render_mesh(mesh, self.view, self.size, self.margin)
        if not render.mask.any():
            raise InputError(f"{self.mesh_path}: nothing is visible from view {self.view}")
        try:
            image = render_colours(mesh, render)
        except InputError as exc:
            raise InputError(f"{self.mesh_path}: {exc} (an example needs colours)") from exc
        arrays = {"depth": render.depth, "image": image}
        arrays.update({f"map_{k}": v for k, v in maps_seen(mesh, render).items()})
        try:
            write_npz(cached, **arrays)
        except OSError:
            pass  # a read-only cache only costs time
        self._arrays.update(arrays)
        return self._arrays

    @property
    def depth(self) -> np.ndarray:
        return self._render()["depth"]

    @property
    def image(self) -> np.ndarray:
        return self._render()["image"]

    @property
    def labels(self) -> np.ndarray | None:
        return None

    def map_kinds(self) -> list[str]:
        """The PBR maps this mesh's material carries (roughness, metallic, ao, normal)."""

        if "map_kinds" not in self._arrays:
            material = getattr(load_mesh(self.mesh_path).visual, "material", None)
            self._arrays["map_kinds"] = sorted(_material_maps(material)) if material else []
        return list(self._arrays["map_kinds"])

    def rendered_maps(self) -> dict[str, np.ndarray]:
        """The material's maps seen from this example's view, like its image-map
        (rendered and cached with it; see :func:`maps_seen`)."""
        arrays = self._render()
        return {k[4:]: v for k, v in arrays.items() if k.startswith("map_")}

    @property
    def info(self) -> dict:
        return {"mesh": str(self.mesh_path), "view": str(self.view)}

    def __repr__(self) -> str:
        return f"MeshExample({self.name!r}, {self.mesh_path.name!r}, view={self.view})"


def maps_seen(mesh, render) -> dict[str, np.ndarray]:
    """A mesh material's PBR maps as ``render`` sees them: grey maps sampled at each
    pixel's UVs; the normal map turned from the mesh's UV tangent frame into the
    picture's (:func:`imagemap.materials.atlas_normals_to_view`)."""

    maps = _material_maps(getattr(mesh.visual, "material", None))
    uv = getattr(mesh.visual, "uv", None)
    if not maps or uv is None:
        return {}
    pixels = np.flatnonzero(render.mask)
    faces = render.face.flat[pixels]
    bary = render.barycentric.reshape(-1, 3)[pixels].astype(np.float64)
    point_uv = np.einsum("nk,nkc->nc", bary, np.asarray(uv)[mesh.faces[faces]])
    point_uv -= np.floor(point_uv)
    height, width = render.depth.shape
    out = {}
    for kind, texture in maps.items():
        channels = 3 if kind == "normal" else 1
        values = sample_image(texture.reshape(texture.shape[:2] + (channels,)), point_uv)
        if kind == "normal":
            values = atlas_normals_to_view(values, mesh, faces, bary, render.view)
        picture = np.empty((height * width, channels), dtype=np.float32)
        picture[:] = NEUTRAL[kind]
        picture[pixels] = values
        picture = picture.reshape(height, width, channels)
        out[kind] = picture if channels == 3 else picture[..., 0]
    return out


def mesh_examples(
    root: str | os.PathLike,
    view: View | str | None = None,
    size: tuple[int, int] | None = None,
    taken: set[str] | frozenset = frozenset(),
    cache_dir: str | os.PathLike | None = None,
) -> tuple[list[MeshExample], list[str]]:
    """The meshes of a database directory as examples (rendered lazily, cached).

    Returns (examples, problems); a mesh whose name (file stem) is already an
    example's (``taken``) is a problem, not an example.
    """
    root = Path(root)
    view = parse_view(view)
    examples: list[MeshExample] = []
    problems: list[str] = []
    if not root.is_dir():
        return examples, problems
    for entry in sorted(root.iterdir()):
        if not entry.is_file() or not is_mesh_path(entry):
            continue
        name = entry.stem
        if name in taken or any(e.name == name for e in examples):
            problems.append(f"{entry}: an example named {name!r} exists already")
            continue
        examples.append(MeshExample(name, entry, view, size or DEFAULT_SIZE, cache_dir))
    return examples, problems
