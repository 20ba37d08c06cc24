"""Copying through a source map: the helpers of every copy-based finish.

A map whose every pixel is copied from an exemplar pixel is described by its source
map (exemplar index, source y, source x per pixel). :func:`copy_through` copies the
exemplars through it and :func:`coherent_edges` tells where neighbours were copied
from neighbouring exemplar pixels; :func:`fill_background` extends an object's values
past its outline and :func:`smooth_inside` smooths within a region only. The copy's
seams are placed by :mod:`imagemap.core.seams` (graph cuts) and blended by
:mod:`imagemap.core.poisson` (a screened Poisson solve).
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

__all__ = [
    "coherent_edges",
    "copy_through",
    "fill_background",
    "nearest_object_pixels",
    "smooth_inside",
]


def fill_background(
    image: np.ndarray, mask: np.ndarray, nearest: np.ndarray | None = None
) -> np.ndarray:
    """Extend the object's values into the background (nearest object pixel).

    A window at the silhouette then carries object-like colours beyond the edge,
    so no background colour bleeds into a synthesised object. A new array always: where
    ``mask`` is all or nothing there is nothing to extend from or into, and the result is
    a copy of ``image``. ``nearest``: :func:`nearest_object_pixels` of ``mask``, when
    several images of one object are filled (the same values, one distance transform).

    Examples
    --------
    >>> image = np.array([[0.0, 5.0, 7.0]]); fill_background(image, image > 0)
    array([[5., 5., 7.]])
    """
    if mask.all() or not mask.any():
        return image.copy()
    ny, nx = nearest_object_pixels(mask) if nearest is None else nearest
    return image[ny, nx]


def nearest_object_pixels(mask: np.ndarray) -> np.ndarray:
    """(2, H, W): each pixel's nearest pixel of ``mask`` (itself inside it), as
    :func:`fill_background` reads it (``ndimage.distance_transform_edt``'s indices)."""
    return ndimage.distance_transform_edt(~mask, return_distances=False, return_indices=True)


def smooth_inside(values: np.ndarray, region: np.ndarray, sigma: float) -> np.ndarray:
    """Gaussian smoothing of ``values`` over ``region`` only (normalized convolution),
    0 outside it: what lies outside (the background past an outline, another part)
    does not bleed in. ``values`` is (H, W), or (H, W, C) smoothed per channel.

    Examples
    --------
    >>> values = np.array([[0.0, 4.0, 4.0, 9.0]])
    >>> smooth_inside(values, values == 4.0, 1.0)
    array([[0., 4., 4., 0.]])
    """
    region = np.asarray(region, bool)
    weight = ndimage.gaussian_filter(region.astype(np.float64), sigma)
    if values.ndim == region.ndim + 1:
        weight = weight[..., None]
        region = region[..., None]
        sigma = (sigma, sigma, 0.0)  # type: ignore[assignment]  # not across channels
    smooth = ndimage.gaussian_filter(np.where(region, values, 0.0), sigma)
    return np.where(region, smooth / np.maximum(weight, 1e-12), 0.0)


def coherent_edges(source: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where neighbouring pixels were copied from neighbouring exemplar pixels.

    Parameters
    ----------
    source : ndarray of int, (H, W, 3)
        Exemplar index, source y, source x per pixel (index < 0: no source).

    Returns
    -------
    horizontal : ndarray of bool, (H, W - 1)
        Pixel (y, x + 1) was copied from the right neighbour of the source of (y, x).
    vertical : ndarray of bool, (H - 1, W)
        Likewise downwards.
    """
    e, sy, sx = source[..., 0], source[..., 1], source[..., 2]
    valid = e >= 0
    horizontal = (
        valid[:, :-1]
        & (e[:, 1:] == e[:, :-1])
        & (sy[:, 1:] == sy[:, :-1])
        & (sx[:, 1:] == sx[:, :-1] + 1)
    )
    vertical = valid[:-1] & (e[1:] == e[:-1]) & (sy[1:] == sy[:-1] + 1) & (sx[1:] == sx[:-1])
    return horizontal, vertical


def copy_through(
    exemplars: list[np.ndarray], source: np.ndarray, dy: int = 0, dx: int = 0, dtype=np.float64
):
    """Each pixel the exemplar value at its source pixel shifted by (dy, dx) (clipped);
    0 where it has no source. ``dtype``: of the copy (float32 exemplars copied as float32
    hold the same values as float64 does, in half the memory)."""
    e, sy, sx = source[..., 0], source[..., 1] + dy, source[..., 2] + dx
    out = np.zeros(source.shape[:2] + exemplars[0].shape[2:], dtype=dtype)
    for k, exemplar in enumerate(exemplars):
        here = e == k
        h, w = exemplar.shape[:2]
        out[here] = exemplar[np.clip(sy[here], 0, h - 1), np.clip(sx[here], 0, w - 1)]
    return out
