"""Textured meshes as database examples: rendered from a view on first use, cached on disk."""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

import numpy as np

from imagemap.example import Example
from imagemap.io import InputError, read_npz, write_npz
from imagemap.mesh.files import file_digest, is_mesh_path, load_mesh
from imagemap.mesh.views import (
    DEFAULT_MARGIN,
    DEFAULT_SIZE,
    FRONT,
    View,
    parse_view,
    render_colours,
    render_mesh,
)

__all__ = ["RENDER_VERSION", "MeshExample", "mesh_examples"]

#: Bumped whenever rendering changes, so cached renders of examples are redone.
RENDER_VERSION = 1


def _default_cache() -> Path:
    root = os.environ.get("IMAGEMAP_CACHE")
    return Path(root) if root else Path.home() / ".cache" / "imagemap"


class MeshExample(Example):
    """An example whose depth and image-map are rendered from a textured mesh.

    Rendered on first use for its view and size, and cached on disk in
    ``cache_dir/meshes/`` under a key of the file's content hash, the view, the size,
    the margin and :data:`RENDER_VERSION`: a changed file or view renders anew.
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
        self.cache_dir = Path(cache_dir) if cache_dir is not None else _default_cache()

    def at_view(self, view: View, size: tuple[int, int] | None = None) -> MeshExample:
        """The same mesh rendered from another view (and size)."""
        return MeshExample(
            self.name, self.mesh_path, view, size or self.size, self.cache_dir, self.margin
        )

    def cache_path(self) -> Path:
        digest = file_digest(self.mesh_path)
        key = f"{digest}|{self.view}|{self.size}|{self.margin}|v{RENDER_VERSION}"
        short = hashlib.sha256(key.encode()).hexdigest()[:24]
        return self.cache_dir / "meshes" / f"{self.name}-{short}.npz"

    def _render(self) -> dict:
        if self._arrays:
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

    @property
    def info(self) -> dict:
        return {"mesh": str(self.mesh_path), "view": str(self.view)}

    def __repr__(self) -> str:
        return f"MeshExample({self.name!r}, {self.mesh_path.name!r}, view={self.view})"


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
