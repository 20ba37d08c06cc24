"""One example of a database: a depth map beside its image-map (and part labels).

Arrays are loaded on first use and cached, so opening a large database costs nothing
until its examples are needed.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np
from scipy import ndimage

from imagemap.io import (
    InputError,
    _load_raw,
    _to_unit_float,
    read_depth,
    read_image,
    validate_depth,
)

__all__ = ["Example"]


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
        """An example held in memory.

        Parameters
        ----------
        name : str
            The example's name.
        depth : ndarray, (H, W)
            Larger is nearer; 0 or NaN is background.
        image : ndarray, (H, W, 3)
            The image-map: float in [0, 1], or uint8 (divided by 255) or uint16
            (divided by 65535). Other integer types, values outside [0, 1], NaN or
            infinite values are refused (:class:`InputError` naming the example).
        labels : ndarray of int, (H, W), optional
            Part ids.
        """
        if not isinstance(name, str) or not name:
            raise InputError(f"example name must be a non-empty string, got {name!r}")
        depth = validate_depth(depth, name=f"example {name!r}")
        image = _image_from_array(np.asarray(image), f"example {name!r}")
        if image.ndim != 3 or image.shape[2] != 3 or image.shape[:2] != depth.shape:
            raise InputError(
                f"example {name!r}: image {image.shape} does not match depth {depth.shape} "
                "(expected (H, W, 3) of the depth's size)"
            )
        arrays = {"depth": depth, "image": image}
        if labels is not None:
            labels = np.asarray(labels)
            if labels.shape != depth.shape or labels.dtype.kind not in "biu":
                raise InputError(
                    f"example {name!r}: labels must be integers of the depth's shape "
                    f"{depth.shape}, got {labels.dtype} {labels.shape}"
                )
            arrays["labels"] = labels.astype(np.int32)
        return cls(name=name, _arrays=arrays)

    @cached_property
    def depth(self) -> np.ndarray:
        if "depth" in self._arrays:
            return self._arrays["depth"]
        return read_depth(self._path("depth_path"))

    @cached_property
    def image(self) -> np.ndarray:
        if "image" in self._arrays:
            return self._arrays["image"]
        image_path = self._path("image_path")
        image = read_image(image_path)
        if image.shape[:2] != self.shape:
            raise InputError(
                f"{image_path}: image is {image.shape[1]}x{image.shape[0]} but its depth "
                f"{self._path('depth_path').name} is {self.shape[1]}x{self.shape[0]}"
            )
        return image

    @cached_property
    def shape(self) -> tuple[int, int]:
        """The depth's (H, W): kept when the arrays are dropped
        (:meth:`imagemap.database.Database.release_arrays`), so reading the image again
        does not read the depth again to check it."""
        height, width = self.depth.shape
        return height, width

    def _path(self, field_name: str) -> Path:
        """The file behind a field (``"depth_path"``...), or :class:`InputError` when the
        example has neither the array nor the file (an ``Example`` built by hand)."""
        path = getattr(self, field_name)
        if path is None:
            raise InputError(
                f"example {self.name!r}: no {field_name.removesuffix('_path')} array or file "
                "(build examples with Example.from_arrays or Database.from_directory)"
            )
        return path

    @cached_property
    def labels(self) -> np.ndarray | None:
        if "labels" in self._arrays:
            return self._arrays["labels"]
        if self.labels_path is None:
            return None
        labels = _load_raw(self.labels_path)
        if labels.ndim == 3:
            labels = labels[..., 0]
        if labels.dtype.kind not in "biu":
            raise InputError(
                f"{self.labels_path}: part labels must be integers, got {labels.dtype}"
            )
        if labels.shape != self.depth.shape:
            raise InputError(f"{self.labels_path}: labels {labels.shape} differ from the depth")
        return labels.astype(np.int32)

    @cached_property
    def info(self) -> dict:
        """The instance's JSON sidecar (parts, colours, parameters), or {}."""
        if self.json_path is None:
            return {}
        try:
            info = json.loads(self.json_path.read_text())
        except (OSError, ValueError) as exc:
            raise InputError(f"{self.json_path}: cannot be read as JSON ({exc})") from exc
        if not isinstance(info, dict):
            raise InputError(f"{self.json_path}: expected a JSON object, got {type(info).__name__}")
        return info

    @property
    def mask(self) -> np.ndarray:
        return self.depth > 0

    @cached_property
    def selection_stats(self) -> tuple[np.ndarray, float]:
        """(centroid (y, x) of the foreground, sum of squared depth): what example
        selection needs of this example, computed once (not once per query)."""
        depth = self.depth
        centroid = np.array(ndimage.center_of_mass(depth > 0), dtype=np.float64)
        return centroid, float(np.square(depth, dtype=np.float64).sum())


def _image_from_array(image: np.ndarray, name: str) -> np.ndarray:
    """An image-map array as float32 in [0, 1]: uint8 / 255, uint16 / 65535, floats checked."""
    if image.dtype == bool or not (
        np.issubdtype(image.dtype, np.integer) or np.issubdtype(image.dtype, np.floating)
    ):
        raise InputError(
            f"{name}: image must be float in [0, 1], uint8 or uint16, got {image.dtype}"
        )
    if np.issubdtype(image.dtype, np.integer) and image.dtype not in (np.uint8, np.uint16):
        raise InputError(
            f"{name}: image of {image.dtype}: give float in [0, 1], uint8 (0-255) or uint16"
        )
    image = _to_unit_float(image, name)
    if not np.all(np.isfinite(image)):
        raise InputError(f"{name}: image has NaN or infinite values")
    low, high = float(image.min(initial=0.0)), float(image.max(initial=0.0))
    if low < 0.0 or high > 1.0:
        raise InputError(
            f"{name}: image values span [{low:g}, {high:g}]; expected [0, 1] "
            "(divide 0-255 values by 255, or pass a uint8 array)"
        )
    return image
