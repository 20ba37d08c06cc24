"""A mapping: one pyramid level of guide bands, appearance bands and a mask."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Mapping", "ReleasableLevels"]


@dataclass(frozen=True)
class Mapping:
    """One pyramid level of a query or exemplar: guide, appearance and mask.

    Parameters
    ----------
    guide : ndarray, shape (H, W, Cg) or (H, W)
        Bands known for query and exemplars (depth bands, constraint images...).
    appearance : ndarray, shape (H, W, Ca) or (H, W), optional
        Bands to synthesise: given for exemplars, None for the query.
    mask : ndarray of bool, shape (H, W), optional
        Where the mapping matters (the object); None means everywhere.
    position : ndarray, shape (H, W, 2), optional
        Where each pixel lies in a frame common to the query and the exemplars
        (y, x), in units of the query object's size: the engine's position term
        compares these. None: the pixel's position relative to the mask's centroid,
        in units of the mask's RMS radius (Hassner & Basri's relative position). A
        front end that has registered its exemplars onto the query gives each
        exemplar pixel the query position it corresponds to.
    position_scale : ndarray, shape (H, W), optional
        The query's own factor (>= 0) per pixel on the position term's weight: less
        where the front end trusts the position less (None: 1 everywhere). Exemplars
        have none.
    origin : (int, int)
        Where the arrays' first row and column lie in the exemplar's whole frame: an
        exemplar's mapping may be a crop of its frame (the object and the margin its
        windows read), so that the frame is not held whole. The engine works and
        answers (sources, positions) in frame coordinates: the same as with the whole
        frame as long as no window it reads crosses a side of the crop that is not a
        side of the frame (it checks). Needs a mask.
    frame_shape : (int, int), optional
        The whole frame's (H, W); None: the arrays' own (no crop).
    """

    guide: np.ndarray
    appearance: np.ndarray | None = None
    mask: np.ndarray | None = None
    position: np.ndarray | None = None
    position_scale: np.ndarray | None = None
    origin: tuple[int, int] = (0, 0)
    frame_shape: tuple[int, int] | None = None

    def __post_init__(self) -> None:
        guide = np.asarray(self.guide, dtype=np.float32)
        if guide.ndim == 2:
            guide = guide[..., None]
        if guide.ndim != 3:
            raise ValueError(f"guide must be (H, W) or (H, W, C), got shape {guide.shape}")
        object.__setattr__(self, "guide", guide)
        if self.appearance is not None:
            appearance = np.asarray(self.appearance, dtype=np.float32)
            if appearance.ndim == 2:
                appearance = appearance[..., None]
            if appearance.shape[:2] != guide.shape[:2]:
                raise ValueError(
                    f"appearance {appearance.shape[:2]} and guide {guide.shape[:2]} differ in size"
                )
            object.__setattr__(self, "appearance", appearance)
        if self.mask is not None:
            mask = np.asarray(self.mask, dtype=bool)
            if mask.shape != guide.shape[:2]:
                raise ValueError(f"mask {mask.shape} and guide {guide.shape[:2]} differ in size")
            if not mask.any():
                raise ValueError("mask is empty")
            object.__setattr__(self, "mask", mask)
        if self.position is not None:
            position = np.asarray(self.position, dtype=np.float32)
            if position.shape != guide.shape[:2] + (2,):
                raise ValueError(
                    f"position must be (H, W, 2) of the guide's size, got {position.shape}"
                )
            if not np.all(np.isfinite(position)):
                raise ValueError("position has NaN or infinite values")
            object.__setattr__(self, "position", position)
        if self.position_scale is not None:
            scale = np.asarray(self.position_scale, dtype=np.float32)
            if scale.shape != guide.shape[:2]:
                raise ValueError(
                    f"position_scale must be (H, W) of the guide's size, got {scale.shape}"
                )
            if not np.all(np.isfinite(scale)) or np.any(scale < 0):
                raise ValueError("position_scale must be finite and not negative")
            object.__setattr__(self, "position_scale", scale)
        origin = (int(self.origin[0]), int(self.origin[1]))
        frame = guide.shape[:2] if self.frame_shape is None else tuple(self.frame_shape)
        if (
            len(frame) != 2
            or min(origin) < 0
            or origin[0] + guide.shape[0] > frame[0]
            or origin[1] + guide.shape[1] > frame[1]
        ):
            raise ValueError(f"a crop at {origin} of {guide.shape[:2]} is not inside {frame}")
        if frame != guide.shape[:2] and self.mask is None:
            raise ValueError("a cropped mapping needs a mask")
        object.__setattr__(self, "origin", origin)
        object.__setattr__(self, "frame_shape", (int(frame[0]), int(frame[1])))

    @property
    def shape(self) -> tuple[int, int]:
        """The arrays' (H, W) (a crop's own, see ``origin``)."""
        return self.guide.shape[:2]

    @property
    def frame(self) -> tuple[int, int]:
        """The whole frame's (H, W): the engine's coordinates."""
        assert self.frame_shape is not None  # set by __post_init__
        return self.frame_shape


class ReleasableLevels(list):
    """A pyramid (list of :class:`Mapping`, finest first) handed over to :func:`synthesize`:
    once the engine has packed a level's bands it calls :meth:`release`, which drops the
    level from the list, so that its arrays are freed during the synthesis if nothing
    else holds them. A plain list is left as it is."""

    def release(self, level: int) -> None:
        self[level] = None
