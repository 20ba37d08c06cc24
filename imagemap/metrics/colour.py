"""Colour measures of a synthesized image-map against the true one: the results table's.

Three measures, all restricted to the object (non-background depth):

- **CIEDE2000**: mean colour difference ΔE00 in CIELAB (``skimage.color``). About 1
  is a just-noticeable difference, 2-10 is noticeable at a glance, above about 20
  the colours are of different kinds.
- **SSIM on luminance** (``skimage.metrics.structural_similarity``) over the
  object's bounding box, averaged over the object's pixels only: structure
  (edges, stripes, spots) in the right places, whatever the exact hue.
- **Part accuracy** (where part labels exist): the fraction of object pixels whose
  synthesized colour is nearer to one of the true colours of its own part than
  to any true colour of another part present (a part's true colours are those
  the truth shows on it: a striped part has several). A map that paints the
  belly's colour on the back loses those pixels.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial import cKDTree
from skimage import color
from skimage.metrics import structural_similarity

from imagemap.io import InputError

__all__ = ["ciede2000", "luminance_ssim", "part_accuracy"]


def _check(image: np.ndarray, truth: np.ndarray, mask: np.ndarray) -> tuple:
    image = np.asarray(image, dtype=np.float32)
    truth = np.asarray(truth, dtype=np.float32)
    mask = np.asarray(mask, dtype=bool)
    if image.shape != truth.shape or image.ndim != 3 or image.shape[2] != 3:
        raise InputError(f"image {image.shape} and truth {truth.shape} must both be (H, W, 3)")
    if mask.shape != image.shape[:2]:
        raise InputError(f"mask {mask.shape} does not match the images {image.shape[:2]}")
    if not mask.any():
        raise InputError("the mask is empty: no object pixels to measure")
    return np.clip(image, 0, 1), np.clip(truth, 0, 1), mask


def ciede2000(image: np.ndarray, truth: np.ndarray, mask: np.ndarray) -> float:
    """Mean CIEDE2000 colour difference between two RGB images over ``mask``.

    Parameters
    ----------
    image, truth : ndarray, (H, W, 3) in [0, 1]
        Synthesized and true image-maps (sRGB).
    mask : ndarray of bool, (H, W)
        The object's pixels.

    Returns
    -------
    float
        Mean ΔE00 (0 for identical colours).

    Example
    -------
    >>> a = np.zeros((4, 4, 3), np.float32); ciede2000(a, a, np.ones((4, 4), bool))
    0.0
    """
    image, truth, mask = _check(image, truth, mask)
    difference = color.deltaE_ciede2000(color.rgb2lab(truth[mask]), color.rgb2lab(image[mask]))
    return float(np.mean(difference, dtype=np.float64))


def luminance_ssim(image: np.ndarray, truth: np.ndarray, mask: np.ndarray) -> float:
    """SSIM of the luminances, over the object's bounding box, averaged over ``mask``.

    Background pixels are set to black in both images first, so that the
    silhouette (identical in both) does not count as structure either way.

    Parameters
    ----------
    image, truth : ndarray, (H, W, 3) in [0, 1]
    mask : ndarray of bool, (H, W)

    Returns
    -------
    float
        Mean SSIM over the object's pixels (1 for identical images).

    Example
    -------
    >>> a = np.random.default_rng(0).random((16, 16, 3))
    >>> round(luminance_ssim(a, a, np.ones((16, 16), bool)), 6)
    1.0
    """
    image, truth, mask = _check(image, truth, mask)
    ys, xs = np.nonzero(mask)
    # A margin of half the 7x7 SSIM window, so border windows see the silhouette.
    margin = 3
    y0, y1 = max(ys.min() - margin, 0), min(ys.max() + margin + 1, mask.shape[0])
    x0, x1 = max(xs.min() - margin, 0), min(xs.max() + margin + 1, mask.shape[1])
    box = mask[y0:y1, x0:x1]
    luma_image = np.where(box, color.rgb2gray(image[y0:y1, x0:x1]), 0.0)
    luma_truth = np.where(box, color.rgb2gray(truth[y0:y1, x0:x1]), 0.0)
    window = min(7, *(s - (1 - s % 2) for s in box.shape))
    if window < 3:
        raise InputError(f"object bounding box {box.shape} is too small for SSIM (at least 3x3)")
    _, ssim_map = structural_similarity(
        luma_truth, luma_image, data_range=1.0, win_size=window, full=True
    )
    return float(ssim_map[box].mean(dtype=np.float64))


def part_accuracy(image: np.ndarray, truth: np.ndarray, labels: np.ndarray) -> float:
    """Fraction of object pixels coloured nearer to their own part's true colours than to others'.

    A part's true colours are the colours the truth shows on that part (a part
    may be striped or spotted, so one mean colour would misjudge the truth
    itself). A pixel is right when its synthesized colour is at least as near to
    one of its own part's true colours as to any colour of another part present.
    Distances are Euclidean in CIELAB (ΔE76), which a k-d tree searches exactly;
    identical images therefore score 1 unless two parts share a colour exactly.

    Parameters
    ----------
    image, truth : ndarray, (H, W, 3) in [0, 1]
    labels : ndarray of int, (H, W)
        Part ids; 0 is background.

    Returns
    -------
    float
        In [0, 1]; NaN when fewer than two parts are present (nothing to confuse).

    Example
    -------
    >>> truth = np.zeros((2, 2, 3), np.float32); truth[0] = (1, 0, 0); truth[1] = (0, 0, 1)
    >>> labels = np.array([[1, 1], [2, 2]])
    >>> part_accuracy(truth[::-1], truth, labels)   # the two parts swapped
    0.0
    """
    labels = np.asarray(labels)
    image, truth, mask = _check(image, truth, labels > 0)
    part_ids, inverse = np.unique(labels[mask], return_inverse=True)
    if len(part_ids) < 2:
        return math.nan
    # 1/64 of a Lab unit merges float noise, so each part's tree holds its distinct colours.
    lab_truth = np.round(color.rgb2lab(truth[mask]) * 64.0) / 64.0
    lab_image = color.rgb2lab(image[mask])
    distances = np.empty((len(inverse), len(part_ids)))
    for p in range(len(part_ids)):
        colours = np.unique(lab_truth[inverse == p], axis=0)
        distances[:, p], _ = cKDTree(colours).query(lab_image)
    own = distances[np.arange(len(inverse)), inverse].copy()
    distances[np.arange(len(inverse)), inverse] = np.inf
    return float(np.mean(own <= distances.min(axis=1) + 1e-9))
