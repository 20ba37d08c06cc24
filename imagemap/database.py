"""Databases of examples on disk: pairs of depth map and image-map.

A database is a directory of ``NAME_depth.png`` (8- or 16-bit), ``NAME_depth.tif``
(float) or ``NAME_depth.npy`` beside ``NAME_image.png``. Other files
(``NAME_labels.png``, ``NAME.json``, contact sheets) may sit beside them and are
read when present. Arrays are loaded on first use and cached, so opening a large
database costs nothing until its examples are needed.
"""

from __future__ import annotations

import json
import os
import re
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np

from imagemap.io import InputError, read_depth, read_image, validate_depth

__all__ = ["Database", "Example", "check_database"]

_DEPTH_RE = re.compile(r"^(?P<name>.+)_depth\.(?:png|tif|tiff|npy)$", re.IGNORECASE)
_IMAGE_RE = re.compile(r"^(?P<name>.+)_image\.(?:png|jpg|jpeg|tif|tiff)$", re.IGNORECASE)


@dataclass
class Example:
    """One example mapping: a depth map and its image-map (and labels if present).

    Build from files with :meth:`Database.from_directory`, or from arrays with
    :meth:`from_arrays`. Arrays are read on first access and cached.
    """

    name: str
    depth_path: Path | None = None
    image_path: Path | None = None
    labels_path: Path | None = None
    json_path: Path | None = None
    _arrays: dict = field(default_factory=dict, repr=False)

    @classmethod
    def from_arrays(
        cls,
        name: str,
        depth: np.ndarray,
        image: np.ndarray,
        labels: np.ndarray | None = None,
    ) -> Example:
        """An example held in memory (depth (H, W), image (H, W, 3) in [0, 1])."""
        depth = validate_depth(depth, name=f"example {name!r}")
        image = np.asarray(image, dtype=np.float32)
        if image.ndim != 3 or image.shape[2] != 3 or image.shape[:2] != depth.shape:
            raise InputError(
                f"example {name!r}: image {image.shape} does not match depth {depth.shape}"
            )
        arrays = {"depth": depth, "image": image}
        if labels is not None:
            arrays["labels"] = np.asarray(labels)
        return cls(name=name, _arrays=arrays)

    @cached_property
    def depth(self) -> np.ndarray:
        if "depth" in self._arrays:
            return self._arrays["depth"]
        return read_depth(self.depth_path)

    @cached_property
    def image(self) -> np.ndarray:
        if "image" in self._arrays:
            return self._arrays["image"]
        image = read_image(self.image_path)
        if image.shape[:2] != self.depth.shape:
            raise InputError(
                f"{self.image_path}: image is {image.shape[1]}x{image.shape[0]} but its depth "
                f"{self.depth_path.name} is {self.depth.shape[1]}x{self.depth.shape[0]}"
            )
        return image

    @cached_property
    def labels(self) -> np.ndarray | None:
        if "labels" in self._arrays:
            return self._arrays["labels"]
        if self.labels_path is None:
            return None
        import imageio.v3 as iio

        labels = iio.imread(self.labels_path)
        if labels.ndim == 3:
            labels = labels[..., 0]
        if labels.shape != self.depth.shape:
            raise InputError(f"{self.labels_path}: labels {labels.shape} differ from the depth")
        return labels.astype(np.int32)

    @cached_property
    def info(self) -> dict:
        """The instance's JSON sidecar (parts, colours, parameters), or {}."""
        if self.json_path is None:
            return {}
        try:
            return json.loads(self.json_path.read_text())
        except (OSError, ValueError) as exc:
            raise InputError(f"{self.json_path}: cannot be read as JSON ({exc})") from exc

    @property
    def mask(self) -> np.ndarray:
        return self.depth > 0


class Database:
    """An ordered collection of examples (sorted by name).

    Examples
    --------
    >>> db = Database.from_directory("examples/fish")  # doctest: +SKIP
    >>> db.names[:2]  # doctest: +SKIP
    ['fish_000', 'fish_001']
    """

    def __init__(self, examples: list[Example], source: str = "") -> None:
        names = [e.name for e in examples]
        if len(set(names)) != len(names):
            raise InputError(f"{source or 'database'}: duplicate example names")
        self.examples = sorted(examples, key=lambda e: e.name)
        self.source = source

    @classmethod
    def from_directory(
        cls, path: str | os.PathLike, strict: bool = True, view=None, size=None
    ) -> Database:
        """Open a database directory; with ``strict``, unpaired files are an error.

        Textured meshes in it (``NAME.glb``, ``.obj``, ``.ply``...) are examples too,
        rendered from ``view`` at ``size`` (W, H) on first use (see :mod:`imagemap.mesh`).
        """
        from imagemap.mesh import mesh_examples

        examples, problems = _scan(Path(path))
        meshes, mesh_problems = mesh_examples(path, view, size, {e.name for e in examples})
        examples, problems = examples + meshes, problems + mesh_problems
        if strict and problems:
            raise InputError("; ".join(problems))
        if not examples:
            raise InputError(
                f"{path}: no examples found (expected NAME_depth.png beside NAME_image.png, "
                "or textured meshes)"
            )
        return cls(examples, source=str(path))

    def __len__(self) -> int:
        return len(self.examples)

    def __iter__(self):
        return iter(self.examples)

    def __getitem__(self, key: int | str) -> Example:
        if isinstance(key, str):
            for example in self.examples:
                if example.name == key:
                    return example
            raise InputError(
                f"{self.source or 'database'}: no example named {key!r} "
                f"(have: {', '.join(self.names[:10])}{'...' if len(self) > 10 else ''})"
            )
        return self.examples[key]

    @property
    def names(self) -> list[str]:
        return [e.name for e in self.examples]

    def without(self, *names: str) -> Database:
        """The database less the named examples (for leave-one-out)."""
        return Database([e for e in self.examples if e.name not in names], source=self.source)


def _scan(root: Path) -> tuple[list[Example], list[str]]:
    if not root.exists():
        raise InputError(f"{root}: database directory not found")
    if not root.is_dir():
        raise InputError(f"{root}: not a directory")
    depths: dict[str, Path] = {}
    images: dict[str, Path] = {}
    problems = []
    for entry in sorted(root.iterdir()):
        if not entry.is_file():
            continue
        if match := _DEPTH_RE.match(entry.name):
            name = match["name"]
            if name in depths:
                problems.append(f"{entry}: second depth file for {name!r} ({depths[name].name})")
            depths[name] = entry
        elif match := _IMAGE_RE.match(entry.name):
            images[match["name"]] = entry
    for name in sorted(set(depths) - set(images)):
        problems.append(f"{depths[name]}: no image-map {name}_image.png beside it")
    for name in sorted(set(images) - set(depths)):
        problems.append(f"{images[name]}: no depth map {name}_depth.png beside it")
    examples = []
    for name in sorted(set(depths) & set(images)):
        labels = root / f"{name}_labels.png"
        sidecar = root / f"{name}.json"
        examples.append(
            Example(
                name=name,
                depth_path=depths[name],
                image_path=images[name],
                labels_path=labels if labels.exists() else None,
                json_path=sidecar if sidecar.exists() else None,
            )
        )
    return examples, problems


def check_database(path: str | os.PathLike) -> tuple[list[dict], list[str]]:
    """Read every example of a database and report what was found.

    Returns
    -------
    rows : list of dict
        One per readable example: name, size, depth range, foreground fraction,
        whether labels and JSON are present.
    problems : list of str
        One message per problem (unpaired, unreadable, mismatched files).
    """
    examples, problems = _scan(Path(path))
    rows = []
    for example in examples:
        try:
            depth, image = example.depth, example.image
            labels = example.labels
        except InputError as exc:
            problems.append(str(exc))
            continue
        foreground = depth[depth > 0]
        rows.append(
            {
                "name": example.name,
                "size": f"{depth.shape[1]}x{depth.shape[0]}",
                "depth_min": float(foreground.min()),
                "depth_max": float(foreground.max()),
                "foreground": float((depth > 0).mean()),
                "mean_colour": [round(float(c), 3) for c in image[depth > 0].mean(axis=0)],
                "labels": labels is not None,
                "json": example.json_path is not None,
            }
        )
    if not examples and not problems:
        problems.append(f"{path}: no examples found")
    return rows, problems
