"""The fine copy: a map copied again at a finer size through its coarser source map.

Three paths synthesize coarser than they deliver and then copy every fine pixel from the
examples' own, finer detail through the coarse source map (example, y, x per coarse
pixel): the depth maps above the search size (block-averaged by a factor), the uv-space
and registered textures (the working atlas against the output size) and the views
(copied again at the texels' resolution). :func:`fine_positions` is their one copy.

Every fine pixel's source position is the bilinear interpolation of the source
positions at the centres of the four coarse pixels around it. A neighbour enters with
its own position only where it *continues the copy* of the fine pixel's own coarse pixel:
the same example, and its source where the copy's step puts it within ``FINE_DRIFT``
(``max |source step - S pixel step| <= FINE_DRIFT``, ``S`` the example's copy step: the
identity for a translated copy, the pose's turn, scale or mirror for one copied through a
pose; :func:`copy_steps`). One that does not enters with the position the own copy
would give there (the own position moved by ``S`` times the pixel step); a corner one,
the parallelogram of the two beside it (the corner of the copy they show). So

- a translated, turned or mirrored copy (any locally affine one) is reproduced exactly:
  the fine pixels step through the example at its own resolution, with no per-pixel
  derivative to estimate;
- a copy that drifts by one coarse pixel between two coarse pixels steps by one pixel
  at a time, not by the whole factor at their edge;
- two neighbouring patches from other places (another example, or a source more than
  ``FINE_DRIFT`` off the copy's step) are never averaged: the seam stays on the coarse
  pixels' edge, and the copy is not extrapolated beyond its neighbours' positions.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

__all__ = ["FINE_DRIFT", "FinePositions", "copy_steps", "fine_positions"]

#: A neighbour continues a coarse pixel's copy when its source lies at most this many
#: coarse pixels (along each axis) from where the copy's step puts it: a copy drifting by
#: one pixel (as PatchMatch copies drift over a curved object; the fragments' definition
#: of one copy, :data:`imagemap.metrics.coherence.FRAGMENT_DRIFT`) still continues.
FINE_DRIFT = 1.0

#: The eight neighbours' steps (row, column).
_STEPS = [(dy, dx) for dy in (-1, 0, 1) for dx in (-1, 0, 1) if (dy, dx) != (0, 0)]


def copy_steps(source: np.ndarray, examples: int) -> np.ndarray:
    """Each example's copy step (E, 2, 2): d(source y, x) / d(row, column), the median of
    the steps between neighbouring coarse pixels of that example (the identity for an
    example with none): the pose through which a map copies it, turned, scaled or mirrored.

    Examples
    --------
    A mirrored copy: columns run backwards in the example, rows forwards.

    >>> source = np.zeros((3, 4, 3), np.int32)
    >>> source[..., 1] = np.arange(3)[:, None] + 5
    >>> source[..., 2] = 10 - np.arange(4)[None, :]
    >>> copy_steps(source, 1)[0].tolist()
    [[1.0, 0.0], [0.0, -1.0]]
    """
    label = np.asarray(source)[..., 0].astype(np.int64)
    position = np.asarray(source)[..., 1:].astype(np.float64)
    out = np.repeat(np.eye(2)[None], examples, axis=0)
    for axis in (0, 1):
        step = np.diff(position, axis=axis).reshape(-1, 2)
        ahead = (label[1:] if axis == 0 else label[:, 1:]).ravel()
        behind = (label[:-1] if axis == 0 else label[:, :-1]).ravel()
        same = (ahead == behind) & (behind >= 0) & (behind < examples)
        for example in np.unique(behind[same]):
            out[example, :, axis] = np.median(step[same & (behind == example)], axis=0)
    return out


def _neighbour_positions(label: np.ndarray, position: np.ndarray, steps: np.ndarray) -> np.ndarray:
    """For the inner cells of a padded slab: own position (index 4) and the position each
    of the eight neighbours enters the interpolation with, (3, 3, h, w, 2) by step + 1.

    ``label`` (h + 2, w + 2) int (< 0: no source; the padding's), ``position`` (h + 2,
    w + 2, 2) float64, ``steps`` (E, 2, 2) the examples' copy steps.
    """
    height, width = label.shape[0] - 2, label.shape[1] - 2
    own_label = label[1:-1, 1:-1]
    own = position[1:-1, 1:-1]
    step = steps[np.clip(own_label, 0, len(steps) - 1)]  # (h, w, 2, 2)
    step[own_label < 0] = np.eye(2)
    out = np.empty((3, 3, height, width, 2))
    out[1, 1] = own
    found = {}
    for dy, dx in _STEPS:
        other = position[1 + dy : 1 + dy + height, 1 + dx : 1 + dx + width]
        expected = own + step[..., 0] * dy + step[..., 1] * dx
        found[dy, dx] = (
            (label[1 + dy : 1 + dy + height, 1 + dx : 1 + dx + width] == own_label)
            & (own_label >= 0)
            & (np.abs(other - expected).max(axis=-1) <= FINE_DRIFT)
        )
        if not (dy and dx):  # along the axes: else the own copy's step
            out[dy + 1, dx + 1] = np.where(found[dy, dx][..., None], other, expected)
    for dy, dx in _STEPS:  # a corner: else the parallelogram of its two sides
        if dy and dx:
            other = position[1 + dy : 1 + dy + height, 1 + dx : 1 + dx + width]
            extended = out[dy + 1, 1] + out[1, dx + 1] - own
            out[dy + 1, dx + 1] = np.where(found[dy, dx][..., None], other, extended)
    return out


@dataclass(frozen=True)
class FinePositions:
    """Where each fine pixel of a band copies from (:func:`fine_positions`), and which
    coarse pixel it lies in; unpacks as ``index, y, x``.

    Attributes
    ----------
    index : (h, w) int array
        Each fine pixel's example: its own coarse pixel's (< 0 where that has none).
    y, x : (h, w) float64 arrays
        The position read, in the example's coarse pixels (pixel ``j``'s centre at ``j``).
    cell_y : (h,) int64 array
        Each fine row's coarse row (its own coarse pixel's) ...
    cell_x : (w,) int64 array
        ... and each fine column's coarse column.
    within_y, within_x : (h,) and (w,) float64 arrays
        The fine pixel's centre within its coarse pixel, from the coarse pixel's top (left)
        edge, in coarse pixels (0 to 1): where a copy that only translates its own coarse
        pixel reads is that pixel's source plus these.
    """

    index: np.ndarray
    y: np.ndarray
    x: np.ndarray
    cell_y: np.ndarray
    cell_x: np.ndarray
    within_y: np.ndarray
    within_x: np.ndarray

    def __iter__(self) -> Iterator[np.ndarray]:
        return iter((self.index, self.y, self.x))


def fine_positions(
    source: np.ndarray,
    factor: float | tuple[float, float],
    shape: tuple[int, int],
    rows: tuple[int, int] | None = None,
    steps: np.ndarray | None = None,
) -> FinePositions:
    """Where each fine pixel copies from, through a coarse source map.

    Parameters
    ----------
    source : (H, W, 3) array
        The coarse source map: example (< 0: none), y, x in that example's coarse
        picture, per coarse pixel (whole pixels, or any positions).
    factor : float or (float, float)
        Fine pixels per coarse pixel (rows, columns): the fine grid's pixel ``i`` has its
        centre at coarse coordinate ``(i + 0.5) / factor - 0.5``.
    shape : (int, int)
        The fine map's (rows, columns).
    rows : (int, int), optional
        Only the fine rows ``rows[0]`` to ``rows[1] - 1`` (default all): a large map is made
        a band at a time.
    steps : (E, 2, 2) array, optional
        Each example's copy step (:func:`copy_steps`); default the identity (translated
        copies, as the engine makes them).

    Returns
    -------
    FinePositions
        Unpacks as ``index, y, x``: each fine pixel's example (its own coarse pixel's,
        < 0 where that has none) and the position read, in the example's coarse pixels
        (pixel ``j``'s centre at ``j``; a picture ``s`` times finer is read at
        ``(y + 0.5) * s - 0.5``); with each fine row's and column's coarse pixel and the
        fine pixels' places within it.

    Examples
    --------
    A copy turned by 90 degrees (columns run down the example) at twice the size: the fine
    pixels step half a pixel at a time along the turned axes, up to the map's sides.

    >>> source = np.zeros((3, 3, 3), np.int32)
    >>> source[..., 1], source[..., 2] = np.mgrid[:3, :3][::-1]
    >>> source[..., 1] += 5
    >>> _, y, x = fine_positions(source, 2, (6, 6), steps=copy_steps(source, 1))
    >>> y[2].tolist(), x[:, 2].tolist()
    ([4.75, 5.25, 5.75, 6.25, 6.75, 7.25], [-0.25, 0.25, 0.75, 1.25, 1.75, 2.25])
    """
    source = np.asarray(source)
    coarse_rows, coarse_cols = source.shape[:2]
    fy, fx = (float(f) for f in np.broadcast_to(np.asarray(factor, dtype=np.float64), (2,)))
    first, last = (0, int(shape[0])) if rows is None else (int(rows[0]), int(rows[1]))

    def axis(start: int, stop: int, ratio: float, n: int):
        # Each fine pixel's coarse pixel and its place in it from its edge (0 to 1).
        u = (np.arange(start, stop) + 0.5) / float(ratio)
        cell = np.clip(np.floor(u).astype(np.int64), 0, n - 1)
        return cell, u - cell

    cy, within_y = axis(first, last, fy, coarse_rows)
    cx, within_x = axis(0, int(shape[1]), fx, coarse_cols)
    # The offset from the coarse pixel's centre (u - 0.5 - cell, to the bit: u - cell is
    # exact, and so is taking 0.5 from it).
    oy, ox = within_y - 0.5, within_x - 0.5
    if cy.size == 0:
        empty = np.zeros((0, cx.size))
        return FinePositions(
            empty.astype(np.int64), empty, empty.copy(), cy, cx, within_y, within_x
        )
    # The coarse rows of this band's pixels, with a row on either side and a column on
    # either side (no source beyond the map).
    low, high = int(cy.min()), int(cy.max()) + 1
    label = np.full((high - low + 2, coarse_cols + 2), -1, dtype=np.int64)
    position = np.zeros((high - low + 2, coarse_cols + 2, 2))
    top, bottom = max(low - 1, 0), min(high + 1, coarse_rows)
    label[top - low + 1 : bottom - low + 1, 1:-1] = source[top:bottom, :, 0]
    position[top - low + 1 : bottom - low + 1, 1:-1] = source[top:bottom, :, 1:]
    examples = max(int(source[..., 0].max()) + 1, 1)
    if steps is None:
        steps = np.repeat(np.eye(2)[None], examples, axis=0)
    near = _neighbour_positions(label, position, np.asarray(steps, dtype=np.float64))
    ry = (cy - low)[:, None]
    rx = cx[None, :]
    sy = np.where(oy < 0, 0, 2)[:, None]  # the neighbour's index (step + 1) on each axis
    sx = np.where(ox < 0, 0, 2)[None, :]
    wy = np.abs(oy)[:, None, None]
    wx = np.abs(ox)[None, :, None]
    position = (
        near[1, 1, ry, rx] * ((1 - wy) * (1 - wx))
        + near[sy, 1, ry, rx] * (wy * (1 - wx))
        + near[1, sx, ry, rx] * ((1 - wy) * wx)
        + near[sy, sx, ry, rx] * (wy * wx)
    )
    index = source[cy][:, cx, 0].astype(np.int64)
    return FinePositions(index, position[..., 0], position[..., 1], cy, cx, within_y, within_x)
