"""The scanner's colour response fitted from a scanned colour chart (Table 1's model).

The cross-device paper measured its scanner against an X-Rite ColorChecker and gives
the result as per-channel offset o, multiplier m and gamma (Table 1):
linear = m * max(scan - o, 0) ** gamma. :func:`fit_chart_response` finds those three
numbers per channel from a scan of a ColorChecker, so the scans of another scanner
need not borrow the paper's constants.

The chart scan is cropped to the chart's outer edge (any of the four 90-degree turns:
the one that fits best is used) and shows the classic 4 x 6 patches; the value of a
patch is the median of the central half of its grid cell. Fitting minimizes the
error in scan units (where a scanner's noise is), o + (L / m) ** (1 / gamma) - scan,
over the 24 patches, started from a grid over o with (log m, gamma) solved linearly.

Example
-------
>>> from imagemap.btf.constraints import TABLE1_RESPONSE, scanner_response
>>> linear = colorchecker_linear()[None]  # (1, 24, 3): the patches in a row
>>> scan = scanner_response(linear, response=TABLE1_RESPONSE, bits=None)
>>> fit = fit_scanner_response(scan[0], colorchecker_linear())
>>> [round(g, 2) for g in fit.response.gammas]
[1.71, 1.83, 1.89]
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from imagemap.btf.constraints import ScannerResponse
from imagemap.io import InputError

__all__ = [
    "COLORCHECKER_NAMES",
    "COLORCHECKER_SRGB8",
    "ChartFit",
    "chart_patch_values",
    "colorchecker_linear",
    "fit_chart_response",
    "fit_scanner_response",
    "srgb_to_linear",
]

#: The 24 ColorChecker Classic patches, row by row (dark skin at the top left).
COLORCHECKER_NAMES = (
    "dark skin", "light skin", "blue sky", "foliage", "blue flower", "bluish green",
    "orange", "purplish blue", "moderate red", "purple", "yellow green", "orange yellow",
    "blue", "green", "red", "yellow", "magenta", "cyan",
    "white 9.5", "neutral 8", "neutral 6.5", "neutral 5", "neutral 3.5", "black 2",
)  # fmt: skip

#: Their standard 8-bit sRGB values (X-Rite's published values, D65).
COLORCHECKER_SRGB8 = np.array(
    [
        [115, 82, 68], [194, 150, 130], [98, 122, 157], [87, 108, 67], [133, 128, 177],
        [103, 189, 170], [214, 126, 44], [80, 91, 166], [193, 90, 99], [94, 60, 108],
        [157, 188, 64], [224, 163, 46], [56, 61, 150], [70, 148, 73], [175, 54, 60],
        [231, 199, 31], [187, 86, 149], [8, 133, 161], [243, 243, 242], [200, 200, 200],
        [160, 160, 160], [122, 122, 121], [85, 85, 85], [52, 52, 52],
    ],
    dtype=np.uint8,
)  # fmt: skip

CHART_ROWS, CHART_COLS = 4, 6


def srgb_to_linear(values: np.ndarray) -> np.ndarray:
    """The sRGB transfer function undone: encoded values in [0, 1] -> linear.

    Example
    -------
    >>> srgb_to_linear(np.array([0.0, 0.5, 1.0])).round(4).tolist()
    [0.0, 0.214, 1.0]
    """
    values = np.asarray(values, dtype=np.float64)
    return np.where(values <= 0.04045, values / 12.92, ((values + 0.055) / 1.055) ** 2.4)


def colorchecker_linear() -> np.ndarray:
    """The 24 patches in linear RGB, (24, 3) float64."""
    return srgb_to_linear(COLORCHECKER_SRGB8 / 255.0)


@dataclass(frozen=True)
class ChartFit:
    """A fitted scanner response and how well it fits.

    Attributes
    ----------
    response : ScannerResponse
        Offsets, multipliers and gammas per channel.
    rms_scan_error : tuple of 3 floats
        Root-mean-square residual per channel, in scan units (0..1).
    turns : int
        Quarter turns (``numpy.rot90``) that brought the chart upright (0 for patch arrays).
    """

    response: ScannerResponse
    rms_scan_error: tuple[float, float, float]
    turns: int = 0


def chart_patch_values(
    scan: np.ndarray, *, rows: int = CHART_ROWS, cols: int = CHART_COLS, inner: float = 0.5
) -> np.ndarray:
    """Median colour of each patch of a chart scan cropped to the chart, (rows * cols, 3).

    The image is divided into a rows x cols grid; each value is the median of the
    central ``inner`` fraction (per side) of its cell, so frames and gaps between the
    patches are left out.
    """
    scan = np.asarray(scan, dtype=np.float64)
    if scan.ndim != 3 or scan.shape[2] != 3:
        raise InputError(f"chart: expected an (H, W, 3) image, got shape {scan.shape}")
    height, width = scan.shape[:2]
    if height < 2 * rows or width < 2 * cols:
        raise InputError(f"chart: {height}x{width} is too small for {rows}x{cols} patches")
    if not np.all(np.isfinite(scan)):
        raise InputError("chart: has NaN or infinite values")
    half = (1.0 - inner) / 2
    y0 = np.floor((np.arange(rows) + half) * height / rows).astype(int)
    y1 = np.maximum(np.ceil((np.arange(rows) + 1 - half) * height / rows).astype(int), y0 + 1)
    x0 = np.floor((np.arange(cols) + half) * width / cols).astype(int)
    x1 = np.maximum(np.ceil((np.arange(cols) + 1 - half) * width / cols).astype(int), x0 + 1)
    return np.array(
        [
            np.median(scan[y0[i] : y1[i], x0[j] : x1[j]].reshape(-1, 3), axis=0)
            for i in range(rows)
            for j in range(cols)
        ]
    )


def _fit_channel(scan: np.ndarray, linear: np.ndarray) -> tuple[float, float, float, float]:
    """(o, m, gamma, rms) with linear = m * (scan - o) ** gamma, least squares in scan units."""
    from scipy.optimize import least_squares  # deferred: scipy.optimize, the chart fit only

    log_l = np.log(linear)
    # Start: a grid over o; for each, log L = log m + gamma log(s - o) is linear.
    offsets = np.linspace(-0.1, scan.min() - 1e-3, 64)[:, None]
    log_s = np.log(scan[None, :] - offsets)  # (grid, n)
    s_mean, l_mean = log_s.mean(axis=1, keepdims=True), log_l.mean()
    gamma = np.sum((log_s - s_mean) * (log_l - l_mean), axis=1, keepdims=True)
    gamma = gamma / np.maximum(np.sum((log_s - s_mean) ** 2, axis=1, keepdims=True), 1e-12)
    gamma = np.clip(gamma, 0.2, 5.0)
    log_m = l_mean - gamma * s_mean
    predicted = offsets + np.exp((log_l[None] - log_m) / gamma)
    best = int(np.argmin(np.sum((predicted - scan) ** 2, axis=1)))
    start = np.array([offsets[best, 0], log_m[best, 0], gamma[best, 0]])

    def residual(p: np.ndarray) -> np.ndarray:
        o, lm, g = p
        return o + np.exp((log_l - lm) / g) - scan

    lower, upper = np.array([-0.5, -10.0, 0.1]), np.array([0.5, 10.0, 10.0])
    fit = least_squares(residual, np.clip(start, lower + 1e-9, upper - 1e-9), bounds=(lower, upper))
    o, lm, g = fit.x
    return float(o), float(np.exp(lm)), float(g), float(np.sqrt(np.mean(fit.fun**2)))


def fit_scanner_response(patches: np.ndarray, reference: np.ndarray) -> ChartFit:
    """Table 1's response from patch values: scan (n, 3) against linear reference (n, 3).

    Raises
    ------
    InputError
        Fewer than four patches, a reference value <= 0, or no variation in a channel.
    """
    patches = np.asarray(patches, dtype=np.float64)
    reference = np.asarray(reference, dtype=np.float64)
    if patches.shape != reference.shape or patches.ndim != 2 or patches.shape[1] != 3:
        raise InputError(
            f"patches, reference: expected equal (n, 3) shapes, got {patches.shape} and "
            f"{reference.shape}"
        )
    if len(patches) < 4:
        raise InputError(f"patches: at least 4 are needed to fit 3 numbers, got {len(patches)}")
    if np.any(reference <= 0) or not np.all(np.isfinite(reference)):
        raise InputError("reference: linear values must be finite and > 0")
    if not np.all(np.isfinite(patches)):
        raise InputError("patches: have NaN or infinite values")
    if np.any(np.ptp(patches, axis=0) < 1e-3):
        raise InputError("patches: a channel hardly varies; is this a scan of the chart?")
    fits = [_fit_channel(patches[:, c], reference[:, c]) for c in range(3)]
    offsets, multipliers, gammas, rms = (tuple(v) for v in zip(*fits, strict=True))
    return ChartFit(ScannerResponse(offsets, multipliers, gammas), rms)


def fit_chart_response(
    scan: np.ndarray, *, reference: np.ndarray | None = None, max_rms: float = 0.03
) -> ChartFit:
    """Fit the scanner response from a scanned ColorChecker (cropped to the chart).

    Parameters
    ----------
    scan : ndarray, (H, W, 3) in [0, 1]
        The chart as the scanner wrote it, in any of the four 90-degree turns.
    reference : ndarray, (24, 3), optional
        Linear values of the patches (default: the standard ColorChecker).
    max_rms : float
        Largest acceptable residual (scan units) of the best turn; beyond it the image
        is not taken for a chart.

    Returns
    -------
    ChartFit

    Example
    -------
    >>> fit = fit_chart_response(read_image("chart_scan.png"))  # doctest: +SKIP
    >>> color_correct(scan, response=fit.response)  # doctest: +SKIP
    """
    reference = colorchecker_linear() if reference is None else np.asarray(reference)
    scan = np.asarray(scan, dtype=np.float64)
    best = None
    for turns in range(4):
        upright = np.rot90(scan, turns)
        if upright.ndim == 3 and upright.shape[0] > upright.shape[1]:
            continue  # the chart is wider than tall
        fit = fit_scanner_response(chart_patch_values(upright), reference)
        score = float(np.mean(fit.rms_scan_error))
        if best is None or score < best[0]:
            best = (score, ChartFit(fit.response, fit.rms_scan_error, turns))
    if best is None:
        raise InputError(f"chart: expected an (H, W, 3) image, got shape {scan.shape}")
    if best[0] > max_rms:
        raise InputError(
            f"chart: the best fit leaves {best[0]:.3f} RMS (scan units) against the "
            f"ColorChecker values; is the image a ColorChecker cropped to its edge?"
        )
    return best[1]
