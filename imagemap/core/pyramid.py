"""Gaussian and Laplacian pyramids that invert exactly.

``skimage.transform.pyramid_laplacian`` stores ``resized - smooth(resized)`` and
cannot be collapsed back into its input. Here level ``i`` of the Laplacian
pyramid is ``G_i - expand(G_{i+1})`` and the coarsest Gaussian level is kept as
the residual, so ``collapse_laplacian(laplacian_pyramid(x)) == x`` to float
precision.

Level ``i + 1`` samples every second pixel of the smoothed level ``i``, so its
shape is ``ceil(H_i / 2) x ceil(W_i / 2)`` and coarse pixel ``(y, x)`` sits on
fine pixel ``(2y, 2x)``: the engine relies on this to propagate source
coordinates between levels.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

__all__ = [
    "collapse_laplacian",
    "expand",
    "gaussian_pyramid",
    "laplacian_bands",
    "laplacian_pyramid",
    "level_shapes",
    "reduce",
]

#: Standard deviation (pixels) of the smoothing before each 2x subsampling.
REDUCE_SIGMA = 1.0
_EXPAND_ROWS = 128  # rows per block of expand()


def reduce(image: np.ndarray, sigma: float = REDUCE_SIGMA) -> np.ndarray:
    """Smooth and take every second pixel: (H, W[, C]) -> (ceil(H/2), ceil(W/2)[, C]).

    ``ndimage.gaussian_filter``'s passes, along the rows' axis and then the columns', in
    float32 as it makes them, but the second pass only on the rows kept (each of its
    values reads its own row alone): the same values, a quarter less filtering.

    Examples
    --------
    >>> image = np.random.default_rng(0).random((9, 7, 2)).astype(np.float32)
    >>> smooth = ndimage.gaussian_filter(image, (1.0, 1.0, 0.0), mode="reflect")
    >>> bool(np.array_equal(reduce(image), smooth[::2, ::2]))
    True
    """
    image = np.asarray(image, dtype=np.float32)
    rows = ndimage.gaussian_filter1d(image, sigma, axis=0, mode="reflect")[::2]
    smooth = ndimage.gaussian_filter1d(rows, sigma, axis=1, mode="reflect")
    return np.ascontiguousarray(smooth[:, ::2])


def expand(image: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Bilinear upsampling of a coarse level onto the finer grid of ``shape``.

    Fine pixel ``(Y, X)`` reads the coarse image at ``(Y / 2, X / 2)``, the inverse
    of the sampling in :func:`reduce`.
    """
    image = np.asarray(image, dtype=np.float32)
    height, width = shape
    ys = np.minimum(np.arange(height, dtype=np.float32) / 2, image.shape[0] - 1)
    xs = np.minimum(np.arange(width, dtype=np.float32) / 2, image.shape[1] - 1)
    y0 = np.floor(ys).astype(np.intp)
    x0 = np.floor(xs).astype(np.intp)
    y1 = np.minimum(y0 + 1, image.shape[0] - 1)
    x1 = np.minimum(x0 + 1, image.shape[1] - 1)
    fy = (ys - y0).reshape((-1, 1) + (1,) * (image.ndim - 2))
    fx = (xs - x0).reshape((1, -1) + (1,) * (image.ndim - 2))
    # In blocks of rows (the same per-pixel float64 arithmetic, rounded to float32 on
    # storing): a full-size map's float64 temporaries would be several times its size.
    out = np.empty((height, width) + image.shape[2:], dtype=np.float32)
    for r0 in range(0, height, _EXPAND_ROWS):
        rows = slice(r0, r0 + _EXPAND_ROWS)
        upper, lower = image[y0[rows]], image[y1[rows]]
        top = upper[:, x0] * (1 - fx) + upper[:, x1] * fx
        bottom = lower[:, x0] * (1 - fx) + lower[:, x1] * fx
        out[rows] = top * (1 - fy[rows]) + bottom * fy[rows]
    return out


def level_shapes(shape: tuple[int, int], levels: int) -> list[tuple[int, int]]:
    """Spatial shapes of the ``levels`` pyramid levels of an image of ``shape``."""
    shapes = [(int(shape[0]), int(shape[1]))]
    for _ in range(levels - 1):
        h, w = shapes[-1]
        shapes.append(((h + 1) // 2, (w + 1) // 2))
    return shapes


def gaussian_pyramid(image: np.ndarray, levels: int = 3) -> list[np.ndarray]:
    """Gaussian pyramid, finest first.

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, C)
    levels : int
        Number of levels including the input itself.

    Returns
    -------
    list of ndarray
        ``levels`` float32 arrays, level ``i`` of shape ``ceil(H / 2**i)``.

    Examples
    --------
    >>> [g.shape for g in gaussian_pyramid(np.zeros((150, 200)), 3)]
    [(150, 200), (75, 100), (38, 50)]
    """
    if levels < 1:
        raise ValueError("levels must be at least 1")
    pyramid = [np.asarray(image, dtype=np.float32)]
    for _ in range(levels - 1):
        pyramid.append(reduce(pyramid[-1]))
    return pyramid


def laplacian_pyramid(image: np.ndarray, levels: int = 3) -> list[np.ndarray]:
    """Invertible Laplacian pyramid, finest first; the last level is the Gaussian residual.

    Examples
    --------
    >>> x = np.random.default_rng(0).random((37, 50, 3)).astype(np.float32)
    >>> bool(np.allclose(collapse_laplacian(laplacian_pyramid(x, 3)), x, atol=1e-6))
    True
    """
    gaussian = gaussian_pyramid(image, levels)
    return laplacian_bands(gaussian) + [gaussian[-1]]


def laplacian_bands(gaussian: list[np.ndarray]) -> list[np.ndarray]:
    """The band-pass levels of :func:`laplacian_pyramid` from its Gaussian pyramid (one
    fewer than its levels): ``G_i - expand(G_{i+1})``, without smoothing it again."""
    return [
        fine - expand(coarse, fine.shape[:2])
        for fine, coarse in zip(gaussian[:-1], gaussian[1:], strict=True)
    ]


def collapse_laplacian(pyramid: list[np.ndarray]) -> np.ndarray:
    """Sum a Laplacian pyramid back into the finest image (inverse of :func:`laplacian_pyramid`)."""
    image = np.asarray(pyramid[-1], dtype=np.float32)
    if len(pyramid) == 1:
        return image.copy()
    for band in reversed(pyramid[:-1]):
        expanded = expand(image, band.shape[:2])
        expanded += band  # band + expanded, without a third full-size array
        image = expanded
    return image.astype(np.float32, copy=False)


def mask_pyramid(mask: np.ndarray, levels: int = 3) -> list[np.ndarray]:
    """Boolean mask pyramid: a coarse pixel is inside when most of its footprint is."""
    return [level >= 0.5 for level in gaussian_pyramid(mask.astype(np.float32), levels)]
