"""The fine copy: a map copied again at a finer size through its coarser source map.

Three paths synthesize coarser than they deliver and then copy every fine pixel from the
examples' own, finer detail through the coarse source map (example, y, x per coarse
pixel): the depth maps above the search size (block-averaged by a factor), the uv-space
and registered textures (the working atlas against the output size) and the views
(copied again at the texels' resolution). :func:`fine_positions` is their one copy.

Every fine pixel's source position is the bilinear interpolation of the source
positions at the centres of the four coarse pixels around it. A neighbour enters with
its own position only where it *continues the copy* of the fine pixel's own coarse pixel
(same example, and the source positions lie about as far apart as the pixels:
``| |source step| - |pixel step| | <= FINE_DRIFT``, the same test for a translated, a
turned or a mirrored copy). One that does not enters with the position the own copy
would give there: the own position extended by the step the copy takes on the other side
(from the mirror neighbour, if that one continues), else by the pixel step (a translated
copy); a corner neighbour that does not continue, with the parallelogram of the two
beside it (the corner of the copy they show). So

- a translated, turned or mirrored copy (any locally affine one) is reproduced exactly,
  up to a seam or the map's side: the fine pixels step through the example at its own
  resolution, with no derivative to estimate;
- a copy that drifts by one coarse pixel between two coarse pixels steps by one pixel
  at a time, not by the whole factor at their edge;
- two neighbouring patches from far-apart places fail the test and are never averaged:
  the seam stays on the coarse pixels' edge.
"""

from __future__ import annotations

import numpy as np

__all__ = ["FINE_DRIFT", "fine_positions"]

#: A neighbour continues a coarse pixel's copy when their source positions' distance
#: differs from their pixels' by at most this many coarse pixels: a copy drifting by one
#: pixel (as PatchMatch copies drift over a curved object; the fragments' definition of
#: one copy, :data:`imagemap.metrics.coherence.FRAGMENT_DRIFT`) still continues.
FINE_DRIFT = 1.0

#: The eight neighbours' steps (row, column).
_STEPS = [(dy, dx) for dy in (-1, 0, 1) for dx in (-1, 0, 1) if (dy, dx) != (0, 0)]


def _neighbour_positions(label: np.ndarray, position: np.ndarray) -> np.ndarray:
    """For the inner cells of a padded slab: own position (index 4) and the position each
    of the eight neighbours enters the interpolation with, (3, 3, h, w, 2) by step + 1.

    ``label`` (h + 2, w + 2) int (< 0: no source; the padding's), ``position`` (h + 2,
    w + 2, 2) float64.
    """
    height, width = label.shape[0] - 2, label.shape[1] - 2
    own_label = label[1:-1, 1:-1]
    own = position[1:-1, 1:-1]
    found, seen = [], []
    for dy, dx in _STEPS:
        other = position[1 + dy : 1 + dy + height, 1 + dx : 1 + dx + width]
        distance = np.hypot(*np.moveaxis(other - own, -1, 0))
        found.append(
            (label[1 + dy : 1 + dy + height, 1 + dx : 1 + dx + width] == own_label)
            & (own_label >= 0)
            & (np.abs(distance - np.hypot(dy, dx)) <= FINE_DRIFT)
        )
        seen.append(other)
    out = np.empty((3, 3, height, width, 2))
    out[1, 1] = own
    for n, (dy, dx) in enumerate(_STEPS):  # along the axes first
        if not (dy and dx):
            m = _STEPS.index((-dy, -dx))  # the mirror neighbour: the copy's step there
            extended = np.where(found[m][..., None], 2 * own - seen[m], own + (dy, dx))
            out[dy + 1, dx + 1] = np.where(found[n][..., None], seen[n], extended)
    for n, (dy, dx) in enumerate(_STEPS):  # a corner: the parallelogram of its two sides
        if dy and dx:
            extended = out[dy + 1, 1] + out[1, dx + 1] - own
            out[dy + 1, dx + 1] = np.where(found[n][..., None], seen[n], extended)
    return out


def fine_positions(
    source: np.ndarray,
    factor: float | tuple[float, float],
    shape: tuple[int, int],
    rows: tuple[int, int] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
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

    Returns
    -------
    index : (h, w) int array
        Each fine pixel's example: its own coarse pixel's (< 0 where that has none).
    y, x : (h, w) float64 arrays
        The position read, in the example's coarse pixels (pixel ``j``'s centre at
        ``j``); a picture ``s`` times finer is read at ``(y + 0.5) * s - 0.5``.

    Examples
    --------
    A copy turned by 90 degrees (columns run down the example) at twice the size: between
    the coarse pixels' centres the fine pixels step half a pixel at a time along the
    turned axes.

    >>> source = np.zeros((3, 3, 3), np.int32)
    >>> source[..., 1], source[..., 2] = np.mgrid[:3, :3][::-1]
    >>> source[..., 1] += 5
    >>> _, y, x = fine_positions(source, 2, (6, 6))
    >>> y[2, 1:5].tolist(), x[1:5, 2].tolist()
    ([5.25, 5.75, 6.25, 6.75], [0.25, 0.75, 1.25, 1.75])
    """
    source = np.asarray(source)
    coarse_rows, coarse_cols = source.shape[:2]
    fy, fx = (float(f) for f in np.broadcast_to(np.asarray(factor, dtype=np.float64), (2,)))
    first, last = (0, int(shape[0])) if rows is None else (int(rows[0]), int(rows[1]))

    def axis(start: int, stop: int, ratio: float, n: int):
        # Each fine pixel's coarse pixel and its offset from that pixel's centre.
        u = (np.arange(start, stop) + 0.5) / float(ratio)
        cell = np.clip(np.floor(u).astype(np.int64), 0, n - 1)
        return cell, u - 0.5 - cell

    cy, oy = axis(first, last, fy, coarse_rows)
    cx, ox = axis(0, int(shape[1]), fx, coarse_cols)
    if cy.size == 0:
        empty = np.zeros((0, cx.size))
        return empty.astype(np.int64), empty, empty.copy()
    # The coarse rows of this band's pixels, with a row on either side and a column on
    # either side (no source beyond the map).
    low, high = int(cy.min()), int(cy.max()) + 1
    label = np.full((high - low + 2, coarse_cols + 2), -1, dtype=np.int64)
    position = np.zeros((high - low + 2, coarse_cols + 2, 2))
    top, bottom = max(low - 1, 0), min(high + 1, coarse_rows)
    label[top - low + 1 : bottom - low + 1, 1:-1] = source[top:bottom, :, 0]
    position[top - low + 1 : bottom - low + 1, 1:-1] = source[top:bottom, :, 1:]
    near = _neighbour_positions(label, position)
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
    return index, position[..., 0], position[..., 1]
