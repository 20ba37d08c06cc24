"""Constraint vectors from four top-view images (the cross-device paper, Sec. 3.2).

Pipeline, for the four images lit from azimuths 0, 90, 180, 270 degrees:

1. scanner colour correction: per channel I_cc = m * max(I - o, 0)^gamma (Table 1),
   which makes the scans radiometrically linear; :func:`scanner_response` is
   its inverse, used to simulate a scanner;
2. histogram alignment (Eqs. 1-2): f_c = mu(I^B, c) / mu(I^S, c), I^S = f_c I^Scc;
3. surface descriptors (Eqs. 3-4): CIELAB L* of each image,
   n~ = [L0 - L180, L270 - L90], each standardized by its mean and std;
4. constraint vectors (Eq. 5): C0 = [ws * n, wc * I0 .. I270] per texel
   (2 + 4 * 3 = 14 bands), extended over a (2R+1)^2 neighbourhood.

All images are linear RGB in (H, W, 3) float32.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np

from imagemap.io import InputError

__all__ = [
    "ScannerResponse",
    "TABLE1_RESPONSE",
    "scanner_response",
    "color_correct",
    "histogram_alignment_factors",
    "align_histograms",
    "lightness",
    "surface_descriptors",
    "constraint_bands",
    "stack_neighbourhood",
    "constraint_vectors",
]


#: ``numpy.pad`` modes :func:`stack_neighbourhood` accepts for the borders.
PadMode = Literal["constant", "edge", "reflect", "symmetric", "wrap"]


@dataclass(frozen=True)
class ScannerResponse:
    """Per-channel offset o, multiplier m and gamma of the colour correction.

    The correction (scan -> linear) is I_cc = m * max(I - o, 0) ** gamma.
    """

    offsets: tuple[float, float, float] = (0.01, 0.01, 0.00)
    multipliers: tuple[float, float, float] = (1.18, 1.14, 1.10)
    gammas: tuple[float, float, float] = (1.71, 1.83, 1.89)


#: The paper's Table 1(b) (Epson Perfection V550 against an X-Rite ColorChecker).
TABLE1_RESPONSE = ScannerResponse()


def _image(image: np.ndarray, name: str) -> np.ndarray:
    array = np.asarray(image, dtype=np.float32)
    if array.ndim != 3 or array.shape[2] != 3:
        raise InputError(f"{name}: expected an (H, W, 3) image, got shape {array.shape}")
    if not np.all(np.isfinite(array)):
        raise InputError(f"{name}: has NaN or infinite values")
    return array


def _four(images: Sequence[np.ndarray], name: str) -> list[np.ndarray]:
    if len(images) != 4:
        raise InputError(
            f"{name}: expected four images (azimuths 0, 90, 180, 270), got {len(images)}"
        )
    out = [_image(im, f"{name}[{i}]") for i, im in enumerate(images)]
    if any(im.shape != out[0].shape for im in out):
        raise InputError(f"{name}: the four images differ in shape {[im.shape for im in out]}")
    return out


def scanner_response(
    linear: np.ndarray,
    *,
    response: ScannerResponse = TABLE1_RESPONSE,
    gain: Sequence[float] = (1.0, 1.0, 1.0),
    noise: float = 0.0,
    bits: int | None = 16,
    seed: int | None = 0,
) -> np.ndarray:
    """Simulate a scan of linear radiance: the inverse of :func:`color_correct`, plus noise.

    scan = o + (gain * linear / m) ** (1 / gamma) + N(0, noise), clipped to [0, 1] and
    quantized to ``bits``.

    Parameters
    ----------
    linear : ndarray, (H, W, 3)
        Linear radiance as the BTF device would measure it.
    response : ScannerResponse
        The device response to invert.
    gain : 3 floats
        The scanner lamp's colour and brightness relative to the BTF device's
        (histogram alignment, Eqs. 1-2, removes it).
    noise : float
        Standard deviation of additive Gaussian noise in scan units.
    bits : int or None
        Quantization (16 as the paper's scans); None keeps floats.
    seed : int or None
        Seed of the noise.

    Returns
    -------
    ndarray, (H, W, 3) float32 in [0, 1]

    Example
    -------
    >>> scan = scanner_response(np.full((2, 2, 3), 0.25, np.float32), bits=None)
    >>> np.allclose(color_correct(scan), 0.25, atol=1e-5)
    True
    """
    linear = _image(linear, "linear")
    o, m, g = (np.asarray(v, dtype=np.float32) for v in _response_arrays(response))
    lit = np.clip(linear * np.asarray(gain, dtype=np.float32), 0.0, None)
    scan = o + (lit / m) ** (1.0 / g)
    if noise > 0:
        rng = np.random.default_rng(seed)
        scan = scan + rng.normal(0.0, noise, size=scan.shape).astype(np.float32)
    scan = np.clip(scan, 0.0, 1.0)
    if bits is not None:
        levels = float(2**bits - 1)
        scan = np.round(scan * levels) / levels
    return scan.astype(np.float32)


def _response_arrays(response: ScannerResponse) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    return (
        np.asarray(response.offsets, dtype=np.float32),
        np.asarray(response.multipliers, dtype=np.float32),
        np.asarray(response.gammas, dtype=np.float32),
    )


def color_correct(scan: np.ndarray, *, response: ScannerResponse = TABLE1_RESPONSE) -> np.ndarray:
    """Scanner colour correction (Sec. 3.2.1): I_cc = m * max(I - o, 0) ** gamma per channel.

    Example
    -------
    >>> round(float(color_correct(np.full((1, 1, 3), 0.51, np.float32))[0, 0, 0]), 4)
    0.3607
    >>> round(1.18 * 0.5**1.71, 4)  # red: m = 1.18, o = 0.01, gamma = 1.71
    0.3607
    """
    scan = _image(scan, "scan")
    o, m, g = _response_arrays(response)
    return (m * np.clip(scan - o, 0.0, None) ** g).astype(np.float32)


def histogram_alignment_factors(
    btf_images: Sequence[np.ndarray], scan_images: Sequence[np.ndarray]
) -> np.ndarray:
    """Eq. 2: f_c = mu(I^B, c) / mu(I^Scc, c), means over all pixels of all images.

    Returns
    -------
    ndarray, (3,) float32

    Example
    -------
    >>> b = [np.ones((2, 2, 3), np.float32)] * 4
    >>> s = [np.full((2, 2, 3), 0.5, np.float32)] * 4
    >>> histogram_alignment_factors(b, s)
    array([2., 2., 2.], dtype=float32)
    """
    btf_mean = np.mean([_image(im, "btf_images").mean(axis=(0, 1)) for im in btf_images], axis=0)
    scan_mean = np.mean([_image(im, "scan_images").mean(axis=(0, 1)) for im in scan_images], axis=0)
    if np.any(scan_mean <= 0):
        raise InputError("scan_images: a channel is black everywhere; cannot align histograms")
    return (btf_mean / scan_mean).astype(np.float32)


def align_histograms(scan_images: Sequence[np.ndarray], factors: np.ndarray) -> list[np.ndarray]:
    """Eq. 1: I^S(x, y, c) = f_c * I^Scc(x, y, c)."""
    factors = np.asarray(factors, dtype=np.float32).reshape(1, 1, 3)
    return [_image(im, "scan_images") * factors for im in scan_images]


def lightness(linear: np.ndarray) -> np.ndarray:
    """CIELAB L* (0..100) of a linear-RGB image, (H, W) float32.

    skimage's ``rgb2lab`` expects gamma-encoded sRGB; our images are linear, so
    they go through the sRGB->XYZ matrix and ``xyz2lab`` directly.
    """
    from skimage.color import xyz2lab  # deferred: skimage, lightness only
    from skimage.color.colorconv import xyz_from_rgb  # deferred: skimage, lightness only

    linear = _image(linear, "image")
    xyz = np.clip(linear, 0.0, None) @ xyz_from_rgb.T.astype(np.float32)
    return xyz2lab(xyz)[..., 0].astype(np.float32)


def surface_descriptors(images: Sequence[np.ndarray]) -> np.ndarray:
    """Eqs. 3-4: standardized L* differences [L0 - L180, L270 - L90], (H, W, 2).

    Parameters
    ----------
    images : four (H, W, 3) linear RGB images lit from azimuths 0, 90, 180, 270.

    Example
    -------
    >>> n = surface_descriptors(four_images)  # doctest: +SKIP
    >>> n.mean(axis=(0, 1)), n.std(axis=(0, 1))  # doctest: +SKIP
    (array([0., 0.]), array([1., 1.]))
    """
    l0, l90, l180, l270 = (lightness(im) for im in _four(images, "images"))
    raw = np.stack([l0 - l180, l270 - l90], axis=2).astype(np.float64)
    mean = raw.mean(axis=(0, 1))
    std = raw.std(axis=(0, 1))
    # A flat material has no shading difference: keep it 0 rather than divide by 0.
    std = np.where(std > 1e-12, std, 1.0)
    return ((raw - mean) / std).astype(np.float32)


def constraint_bands(
    images: Sequence[np.ndarray], *, ws: float = 1.0, wc: float = 1.0
) -> np.ndarray:
    """Eq. 5 per texel: [ws * n1, ws * n2, wc * I0 (RGB), .., wc * I270 (RGB)], (H, W, 14).

    Example
    -------
    >>> bands = constraint_bands(four_images, ws=1.0, wc=10.0)  # doctest: +SKIP
    """
    images = _four(images, "images")
    descriptors = surface_descriptors(images)
    return np.concatenate([ws * descriptors] + [wc * im for im in images], axis=2).astype(
        np.float32
    )


def stack_neighbourhood(
    bands: np.ndarray, *, radius: int = 0, mode: PadMode = "reflect"
) -> np.ndarray:
    """Concatenate each texel's (2R+1)^2 neighbours' bands: (H, W, C * (2R+1)^2).

    Order: neighbour offsets row-major from (-R, -R) to (R, R), the C bands of
    each neighbour together. Borders are padded by ``numpy.pad`` ``mode``.

    Example
    -------
    >>> x = np.arange(9, dtype=np.float32).reshape(3, 3, 1)
    >>> stack_neighbourhood(x, radius=1)[1, 1]
    array([0., 1., 2., 3., 4., 5., 6., 7., 8.], dtype=float32)
    """
    bands = np.asarray(bands, dtype=np.float32)
    if bands.ndim != 3:
        raise InputError(f"bands: expected (H, W, C), got {bands.shape}")
    if radius < 0:
        raise InputError(f"radius: must be >= 0, got {radius}")
    if radius == 0:
        return bands
    height, width, _ = bands.shape
    if mode == "reflect" and (height <= radius or width <= radius):
        raise InputError(f"bands: {height}x{width} too small for radius {radius}")
    padded = np.pad(bands, ((radius, radius), (radius, radius), (0, 0)), mode=mode)
    size = 2 * radius + 1
    windows = np.lib.stride_tricks.sliding_window_view(padded, (size, size), axis=(0, 1))
    # windows: (H, W, C, size, size) -> (H, W, size, size, C) -> (H, W, size*size*C)
    return np.ascontiguousarray(windows.transpose(0, 1, 3, 4, 2)).reshape(height, width, -1)


def constraint_vectors(
    images: Sequence[np.ndarray],
    *,
    ws: float = 1.0,
    wc: float = 1.0,
    radius: int = 0,
) -> np.ndarray:
    """Extended constraint vectors C_R (Eq. 5 over a (2R+1)^2 neighbourhood).

    Parameters
    ----------
    images : four (H, W, 3) linear RGB images (azimuths 0, 90, 180, 270).
    ws, wc : float
        Weights of the surface descriptors and of the colours.
    radius : int
        Neighbourhood radius R.

    Returns
    -------
    ndarray, (H, W, 14 * (2R+1)^2) float32
    """
    return stack_neighbourhood(constraint_bands(images, ws=ws, wc=wc), radius=radius)
