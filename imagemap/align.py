"""Centroid alignment: one object's map moved so that its centroid falls on another's.

Objects are aligned by the centroids of their foreground, as in Hassner & Basri,
*Automatic Depth-Map Colorization* (Eurographics 2006), Sec. 2.3.
Example selection (:func:`imagemap.depth.pipeline.select_examples`), the
``copy_nearest`` baseline and the faulty rule of the evaluation
(:mod:`imagemap.metrics`, :mod:`imagemap.evaluation`) and the preview of
``imagemap synthesize`` all use these functions. Shifts are rounded to whole
pixels; uncovered pixels are zero.

Examples
--------
>>> import numpy as np
>>> source = np.zeros((4, 4), bool); source[0:2, 0:2] = True
>>> target = np.zeros((4, 4), bool); target[2:4, 1:3] = True
>>> centroid_shift(source, target)
array([2., 1.])
>>> paste_aligned(np.ones((4, 4, 3)), source, target)[..., 0].astype(int)
array([[0, 0, 0, 0],
       [0, 0, 0, 0],
       [0, 1, 1, 0],
       [0, 1, 1, 0]])
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

__all__ = [
    "aligned_source",
    "centroid",
    "centroid_shift",
    "paste_aligned",
    "translate",
    "translate_masked",
]


def centroid(mask: np.ndarray) -> np.ndarray:
    """(y, x) centroid of the True pixels of ``mask`` (float64)."""
    return np.array(ndimage.center_of_mass(mask), dtype=np.float64)


def centroid_shift(source_mask: np.ndarray, target_mask: np.ndarray) -> np.ndarray:
    """(dy, dx) that moves the centroid of ``source_mask`` onto that of ``target_mask``."""
    return centroid(target_mask) - centroid(source_mask)


def translate(array: np.ndarray, shift, shape: tuple[int, int]) -> np.ndarray:
    """``array`` (H, W[, C]) translated by the rounded ``shift`` (dy, dx) onto a zero canvas.

    Examples
    --------
    >>> translate(np.ones((2, 2)), (1, 1), (3, 3)).astype(int)
    array([[0, 0, 0],
           [0, 1, 1],
           [0, 1, 1]])
    """
    array = np.asarray(array, dtype=np.float32)
    dy, dx = (int(round(s)) for s in shift)
    out = np.zeros(tuple(shape) + array.shape[2:], dtype=np.float32)
    h, w = array.shape[:2]
    y0, x0 = max(0, dy), max(0, dx)
    y1, x1 = min(shape[0], h + dy), min(shape[1], w + dx)
    if y1 > y0 and x1 > x0:
        out[y0:y1, x0:x1] = array[y0 - dy : y1 - dy, x0 - dx : x1 - dx]
    return out


def translate_masked(
    image: np.ndarray, source_mask: np.ndarray, target_mask: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """``image`` and its object mask moved so that the object's centroid lies on the target's.

    Returns
    -------
    image : ndarray, float32, the target's shape (plus ``image``'s channels)
        The whole image translated (background pixels too).
    covered : ndarray of bool, the target's shape
        Where the translated source object lies.
    """
    shift = centroid_shift(source_mask, target_mask)
    moved = translate(image, shift, target_mask.shape)
    covered = translate(np.asarray(source_mask, dtype=np.float32), shift, target_mask.shape) > 0.5
    return moved, covered


def paste_aligned(
    image: np.ndarray, source_mask: np.ndarray, target_mask: np.ndarray
) -> np.ndarray:
    """``image`` translated so its object's centroid lies on ``target_mask``'s, zero outside.

    This is what a modeller gets by reusing another object's map (Fig. 2d of the
    paper); target pixels with no source colour are black.

    Parameters
    ----------
    image : ndarray, (H, W, 3)
        The source image-map.
    source_mask, target_mask : ndarray of bool
        The source's and the target's object masks.

    Returns
    -------
    ndarray, (H_t, W_t, 3) float32
    """
    source = np.where(source_mask[..., None], image, 0.0)
    shift = centroid_shift(source_mask, target_mask)
    pasted = translate(source, shift, target_mask.shape)
    pasted[~target_mask] = 0.0
    return pasted


def aligned_source(source_mask: np.ndarray, target_mask: np.ndarray, index: int = 0) -> np.ndarray:
    """The source map of :func:`paste_aligned`: (H_t, W_t, 3) int32 of (example, y, x).

    Each target pixel gets ``index`` and the source pixel pasted onto it, or example
    -1 where no source object pixel lands (coordinates clipped at 0), in the layout of
    :attr:`imagemap.depth.pipeline.ColorizeResult.source`.

    Examples
    --------
    >>> source = np.zeros((3, 3), bool); source[0, 0] = True
    >>> target = np.zeros((3, 3), bool); target[1, 1] = True
    >>> source_map = aligned_source(source, target)
    >>> source_map[1, 1].tolist(), int(source_map[0, 0, 0])
    ([0, 0, 0], -1)
    """
    dy, dx = (int(round(s)) for s in centroid_shift(source_mask, target_mask))
    yy, xx = np.mgrid[0 : target_mask.shape[0], 0 : target_mask.shape[1]]
    sy, sx = yy - dy, xx - dx
    inside = (sy >= 0) & (sy < source_mask.shape[0]) & (sx >= 0) & (sx < source_mask.shape[1])
    covered = np.zeros(target_mask.shape, dtype=bool)
    covered[inside] = source_mask[sy[inside], sx[inside]]
    source = np.stack(
        [np.where(covered, index, -1), np.clip(sy, 0, None), np.clip(sx, 0, None)], -1
    )
    return source.astype(np.int32)
