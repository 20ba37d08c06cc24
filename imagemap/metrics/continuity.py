"""Continuity and crispness: a map's luminance structure and mid-tones against the truth's.

Two coherence measures (issue #32, ``docs/measures.md``) read from a map's pixels:
:func:`structure_continuity` (structure-tensor coherence against the truth's: broken
stripes) beside :func:`midtone_share` (mid-tones against the truth's: blur and
ghosting). The measures read from its source map are in :mod:`imagemap.metrics.coherence`.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import ndimage
from skimage import color

from imagemap.core.blend import smooth_inside
from imagemap.io import InputError

__all__ = [
    "COHERENCE_FLAT",
    "CONTINUITY_INTEGRATION",
    "CONTINUITY_MIN_SIGMA",
    "GRAIN_MIN_SIGMA",
    "GRAIN_SCALE",
    "MIDTONE_BAND",
    "MIDTONE_MIN_CONTRAST",
    "MIDTONE_MIN_WINDOW",
    "MIDTONE_WINDOW",
    "midtone_fraction",
    "midtone_share",
    "structure_coherence",
    "structure_continuity",
]


#: Scales of the continuity and crispness measures are shares of the object's size
#: (the square root of its area), so that a map reads the same at every resolution.
#: Both look at the luminance after a Gaussian of GRAIN_SCALE (3 px at 1024^2; never
#: under GRAIN_MIN_SIGMA px, which rules up to about 400x300): per-pixel grain (the
#: outside task's 0.03 noise, +-5 L*) otherwise dominates. Unsmoothed gradients scored
#: a 3 px blur of the truth 2.8x its coherence at 1024^2 and a patchwork of 10 px
#: pieces 1.0-1.15x; with 0.5 px at 200x150 a 1 px blur read 0.74x the truth's
#: mid-tones (docs/measures.md, "How the constants were chosen").
GRAIN_SCALE = 0.005
GRAIN_MIN_SIGMA = 1.0
#: The structure tensor is integrated over a Gaussian of this share of the object
#: (2 px at 200x150, 13 px at 1024^2; at least CONTINUITY_MIN_SIGMA px): a patchwork
#: of 10 px pieces of the truth (offsets within +-5 px) then scores 0.73 / 0.66 / 0.81
#: of the truth at 200x150 / 512^2 / 1024^2, blurs of 1 px to 2 % of the object
#: 0.96-1.01. A share of 0.01 read that patchwork 0.89 at 200x150; 0.05 read a 2 % blur
#: 0.93 at 1024^2.
CONTINUITY_INTEGRATION = 0.02
CONTINUITY_MIN_SIGMA = 1.0
#: Mean squared luminance gradient ((L*/px)^2, after the grain smoothing) below which
#: an image has no structure and no coherence: a constant map's round-off is about
#: 1e-29, the weakest structure measured (the outside task's truth at 1024^2) 1.9.
COHERENCE_FLAT = 1e-6


def _object_side(mask: np.ndarray) -> float:
    return float(np.sqrt(np.count_nonzero(mask)))


def _luminance(image: np.ndarray, channel_axis: int | None) -> np.ndarray:
    """L* (0-100) of an RGB image, or a single-channel image scaled by 100."""
    image = np.asarray(image, dtype=np.float64)
    if channel_axis is None:
        if image.ndim != 2:
            raise InputError(f"image {image.shape} must be (H, W) without a channel axis")
        return np.clip(image, 0, 1) * 100.0
    image = np.moveaxis(image, channel_axis, -1)
    if image.ndim != 3 or image.shape[2] != 3:
        raise InputError(f"image {image.shape} must be RGB (3 channels on channel_axis)")
    return color.rgb2lab(np.clip(image, 0, 1))[..., 0]


def structure_coherence(
    image: np.ndarray,
    mask: np.ndarray,
    *,
    derivative_sigma: float,
    integration_sigma: float,
    channel_axis: int | None = -1,
) -> float:
    """Energy-weighted structure-tensor coherence of an image's luminance over ``mask``.

    The structure tensor J (the outer product of the luminance gradient, Gaussian-
    integrated; as :func:`skimage.feature.structure_tensor`, but with the gradients
    taken inside the mask only) has eigenvalues l1 >= l2; the coherence is
    sum(l1 - l2) / sum(l1 + l2) over the mask: 1 where all structure runs one way
    locally, 0 for isotropic texture. Weighting by the gradient energy l1 + l2 keeps
    flat areas (whose tensor is noise) from counting as much as the stripes.

    Parameters
    ----------
    image : ndarray, (H, W, 3) RGB or (H, W) grey, in [0, 1]
    mask : ndarray of bool, (H, W)
    derivative_sigma, integration_sigma : float
        Gaussian scales (pixels) of the smoothing before the gradient and of the
        tensor's integration.
    channel_axis : int or None
        Axis of the colour channels; None for a grey image.

    Returns
    -------
    float
        In [0, 1]; NaN when the image is flat inside the mask.

    Example
    -------
    >>> stripes = np.tile(np.sin(np.arange(40) / 2.0) > 0, (40, 1)).astype(float)
    >>> c = structure_coherence(stripes, np.ones((40, 40), bool), derivative_sigma=1,
    ...                         integration_sigma=2, channel_axis=None)
    >>> round(c, 3)
    1.0
    """
    mask = np.asarray(mask, dtype=bool)
    luma = smooth_inside(_luminance(image, channel_axis), mask, derivative_sigma)
    inner = ndimage.binary_erosion(mask, np.ones((3, 3), bool))  # the Sobel's footprint
    gy = np.where(inner, ndimage.sobel(luma, 0) / 8.0, 0.0)
    gx = np.where(inner, ndimage.sobel(luma, 1) / 8.0, 0.0)
    jyy, jxx, jxy = (
        ndimage.gaussian_filter(g, integration_sigma) for g in (gy * gy, gx * gx, gx * gy)
    )
    trace = (jxx + jyy)[inner]
    difference = np.sqrt(np.square(jxx - jyy) + 4.0 * np.square(jxy))[inner]  # l1 - l2
    total = float(trace.sum())
    flat = np.mean(np.square(gy[inner]) + np.square(gx[inner])) < COHERENCE_FLAT
    return math.nan if flat or total <= 0 else float(difference.sum()) / total


def structure_continuity(
    image: np.ndarray,
    truth: np.ndarray,
    mask: np.ndarray,
    *,
    grain: float = GRAIN_SCALE,
    integration: float = CONTINUITY_INTEGRATION,
    channel_axis: int | None = -1,
) -> float:
    """Structure-tensor coherence of the map over the truth's (:func:`structure_coherence`).

    Stripes broken into fragments, Y-branches and jagged edges put gradients of
    other directions beside the main one and lower the map's coherence; a blur
    does not change it (so report it beside :func:`midtone_share`). Scales are
    shares of the object's size (``GRAIN_SCALE``, ``CONTINUITY_INTEGRATION``).

    Parameters
    ----------
    image, truth : ndarray, (H, W, 3) RGB in [0, 1] (or grey with ``channel_axis=None``)
    mask : ndarray of bool, (H, W)
        The region measured (the object, or a part of it such as a striped back).
    grain, integration : float
        Gaussian scales (smoothing before the gradients, the tensor's integration) as
        shares of the square root of the mask's area.
    channel_axis : int or None

    Returns
    -------
    float
        1 as orderly as the truth, below 1 less (above 1: more orderly than the truth,
        e.g. its grain smoothed away); NaN when the truth is flat there.

    Example
    -------
    >>> x = np.arange(64)
    >>> stripes = np.tile((np.sin(x / 3.0) > 0).astype(float), (64, 1))
    >>> mask = np.ones((64, 64), bool)
    >>> blurred = ndimage.gaussian_filter(stripes, 2)
    >>> round(structure_continuity(blurred, stripes, mask, channel_axis=None), 2)
    1.0
    """
    mask = np.asarray(mask, dtype=bool)
    if not mask.any():
        raise InputError("the mask is empty: no object pixels to measure")
    side = _object_side(mask)
    derivative_sigma = max(grain * side, GRAIN_MIN_SIGMA)
    integration_sigma = max(integration * side, CONTINUITY_MIN_SIGMA)

    def coherence(picture: np.ndarray) -> float:
        return structure_coherence(
            picture,
            mask,
            derivative_sigma=derivative_sigma,
            integration_sigma=integration_sigma,
            channel_axis=channel_axis,
        )

    reference = coherence(truth)
    if not reference > 0:
        return math.nan
    return coherence(image) / reference


#: Window of the local tones of :func:`midtone_share`, as a share of the object's size
#: (about a stripe's width on the outside task; 11 px at 200x150, 33 px at 1024^2).
#: Measured on the outside task at 200x150 / 512^2 / 1024^2: with 0.05 a crisp copy of
#: the truth shifted by 7 % or 20 % of the object scores 1.01-1.04 of the truth, a 2 %
#: blur 1.9-2.8, two copies 3 % apart averaged 1.7-2.3; in a first study a window of
#: 0.1 read a 1 % blur as 1.1 and one of 0.03 was lost on shifts.
MIDTONE_WINDOW = 0.05
#: The smallest window in pixels: the presets' finest patch width. In smaller windows
#: a crisp edge shifted by a few pixels leaves the truth's edge a window with one tone
#: (a 64 px stripe pattern shifted 5 px read 4.9x its own share with 3 px windows).
MIDTONE_MIN_WINDOW = 7
#: Windows whose tones differ by less than this (L*) have no edge to blur: twice the
#: outside task's grain (+-5 L* unsmoothed), under a third of its stripes' contrast
#: (median window contrast 36 L* at 1024^2).
MIDTONE_MIN_CONTRAST = 10.0
#: A pixel is a mid-tone when its L* lies in this central band of its window's
#: [dark, light] range: the middle half, so that grain on a flat tone (a quarter of a
#: 10 L* minimum contrast is 2.5 L*, about 3x the grain left after smoothing) is not one.
MIDTONE_BAND = (0.25, 0.75)


def _window_tones(luma: np.ndarray, region: np.ndarray, size: int) -> tuple:
    """Darkest and lightest L* of each ``size`` window over ``region``."""
    dark = ndimage.minimum_filter(np.where(region, luma, np.inf), size)
    light = ndimage.maximum_filter(np.where(region, luma, -np.inf), size)
    return dark, light


def midtone_fraction(
    image: np.ndarray,
    mask: np.ndarray,
    *,
    window: int,
    smoothing: float = GRAIN_MIN_SIGMA,
    channel_axis: int | None = -1,
) -> tuple[float, np.ndarray, np.ndarray]:
    """The mid-tone share of one image in its own windows (see :func:`midtone_share`).

    Parameters
    ----------
    image : ndarray, (H, W, 3) RGB in [0, 1] (or grey with ``channel_axis=None``)
    mask : ndarray of bool, (H, W)
    window : int
        Window side in pixels.
    smoothing : float
        Gaussian (pixels) applied to the luminance inside the mask first (the grain).
    channel_axis : int or None

    Returns
    -------
    share : float
        Mid-tone pixels over the pixels whose window has an edge (NaN: none has).
    edges : ndarray of bool
        Pixels whose window's tones differ by ``MIDTONE_MIN_CONTRAST`` or more.
    contrast : ndarray of float
        Each window's light minus dark tone (L*).

    Example
    -------
    >>> step = np.zeros((20, 20)); step[:, 10:] = 1.0
    >>> mask = np.ones((20, 20), bool)
    >>> midtone_fraction(step, mask, window=5, smoothing=0, channel_axis=None)[0]
    0.0
    >>> ramp = ndimage.uniform_filter1d(step, 5, axis=1)  # the edge spread over 5 px
    >>> round(midtone_fraction(ramp, mask, window=5, smoothing=0, channel_axis=None)[0], 2)
    0.5
    """
    mask = np.asarray(mask, dtype=bool)
    luma = smooth_inside(_luminance(image, channel_axis), mask, smoothing)
    middle, edges, contrast = _midtones(luma, mask, window)
    count = int(edges.sum())
    return (int(middle.sum()) / count if count else math.nan), edges, contrast


def _midtones(luma: np.ndarray, mask: np.ndarray, size: int) -> tuple:
    """(mid-tone pixels, edge pixels, window contrast) of an L* image."""
    dark, light = _window_tones(luma, mask, size)
    contrast = np.where(mask, light - dark, 0.0)
    edges = mask & (contrast >= MIDTONE_MIN_CONTRAST)
    position = (luma - dark) / np.maximum(contrast, 1e-9)
    middle = edges & (position > MIDTONE_BAND[0]) & (position < MIDTONE_BAND[1])
    return middle, edges, contrast


def midtone_share(
    image: np.ndarray,
    truth: np.ndarray,
    mask: np.ndarray,
    *,
    window: float = MIDTONE_WINDOW,
    channel_axis: int | None = -1,
) -> float:
    """Mid-tones of the map over the truth's: crispness that sees blur and ghosting.

    The luminance (L*) is first smoothed by ``GRAIN_SCALE`` of the object's size
    (the grain). In each window (``window`` times the object's size) the darkest and
    lightest L* are the local tones; where they differ by ``MIDTONE_MIN_CONTRAST`` or more
    there is an edge, and a pixel there is a *mid-tone* when it lies in the middle
    half of the range. A crisp edge has few (its anti-aliasing, the truth's own
    soft edges); a blurred one or two copies averaged a few pixels apart have a
    ramp of them. Each image is judged in its own tones and its own edges, so a
    palette other than the truth's, stripes drawn with another phase or a plain
    garment where the truth's is checked do not count: this is crispness only.
    Structure the map lacks altogether is for :func:`structure_continuity` and the
    feature and SSIM measures (a map with no edge at all has no mid-tone share).

    Parameters
    ----------
    image, truth : ndarray, (H, W, 3) RGB in [0, 1] (or grey with ``channel_axis=None``)
    mask : ndarray of bool, (H, W)
        The region measured.
    window : float
        Window side as a share of the square root of the mask's area (at least
        ``MIDTONE_MIN_WINDOW`` pixels).
    channel_axis : int or None

    Returns
    -------
    float
        The map's mid-tone share over the truth's: about 1 as crisp as the truth,
        above 1 softer; NaN when the truth has no edge or no mid-tone at all, or the
        map no edge.

    Example
    -------
    >>> x = np.arange(64)
    >>> stripes = np.tile(np.clip(np.sin(x / 4.0) * 3 + 0.5, 0, 1), (64, 1))
    >>> mask = np.ones((64, 64), bool)
    >>> blurred = ndimage.gaussian_filter(stripes, 2)
    >>> midtone_share(blurred, stripes, mask, channel_axis=None) > 1.5
    True
    >>> round(midtone_share(np.roll(stripes, 5, axis=1), stripes, mask, channel_axis=None), 1)
    1.0
    """
    mask = np.asarray(mask, dtype=bool)
    if not mask.any():
        raise InputError("the mask is empty: no object pixels to measure")
    side = _object_side(mask)
    size = max(MIDTONE_MIN_WINDOW, int(round(window * side)) | 1)
    smoothing = max(GRAIN_SCALE * side, GRAIN_MIN_SIGMA)
    truth_share, _, _ = midtone_fraction(
        truth, mask, window=size, smoothing=smoothing, channel_axis=channel_axis
    )
    if not truth_share > 0:
        return math.nan
    share, _, _ = midtone_fraction(
        image, mask, window=size, smoothing=smoothing, channel_axis=channel_axis
    )
    return share / truth_share
