"""A synthetic ColorChecker and its scan through a known scanner response.

The chart is the classic 4 x 6 grid of the standard patch values
(:data:`imagemap.btf.response.COLORCHECKER_SRGB8`) on a dark frame; its scan goes
through :func:`imagemap.btf.constraints.scanner_response` (Table 1's model inverted,
noise, quantization), so a fit of the response can be checked against the truth.

Example
-------
>>> from imagemap.btf.constraints import ScannerResponse
>>> scan = scan_chart(ScannerResponse((0.02, 0.0, 0.01), (1.2, 1.1, 1.0), (1.6, 1.8, 2.0)))
>>> scan.shape
(113, 167, 3)
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from imagemap.btf.constraints import TABLE1_RESPONSE, ScannerResponse, scanner_response
from imagemap.btf.response import CHART_COLS, CHART_ROWS, colorchecker_linear

__all__ = ["chart_image", "scan_chart"]

#: Linear reflectance of the chart's black frame.
FRAME = 0.01


def chart_image(*, patch: int = 22, gap: int = 5, turns: int = 0) -> np.ndarray:
    """The chart in linear RGB, (rows * (patch + gap) + gap, cols * (patch + gap) + gap, 3).

    Parameters
    ----------
    patch, gap : int
        Patch side and the width of the frame between and around the patches (pixels).
    turns : int
        Quarter turns (``numpy.rot90``) of the result, as a chart laid on a scanner.
    """
    if patch < 2 or gap < 0:
        raise ValueError(f"patch >= 2 and gap >= 0 needed, got {patch}, {gap}")
    pitch = patch + gap
    values = colorchecker_linear().reshape(CHART_ROWS, CHART_COLS, 3)
    # Every pixel's cell; pixels in the frame keep FRAME.
    cell = np.repeat(np.repeat(values, pitch, axis=0), pitch, axis=1)
    inside = (np.arange(CHART_ROWS * pitch) % pitch) >= gap
    inside_x = (np.arange(CHART_COLS * pitch) % pitch) >= gap
    image = np.where((inside[:, None] & inside_x[None, :])[..., None], cell, FRAME)
    image = np.pad(image, ((0, gap), (0, gap), (0, 0)), constant_values=FRAME)
    return np.rot90(image, turns).astype(np.float32)


def scan_chart(
    response: ScannerResponse = TABLE1_RESPONSE,
    *,
    patch: int = 22,
    gap: int = 5,
    turns: int = 0,
    gain: Sequence[float] = (1.0, 1.0, 1.0),
    noise: float = 0.0,
    bits: int | None = 16,
    seed: int | None = 0,
) -> np.ndarray:
    """The chart as a scanner with ``response`` writes it, (H, W, 3) float32 in [0, 1].

    ``gain``, ``noise``, ``bits`` and ``seed`` as in
    :func:`imagemap.btf.constraints.scanner_response`.
    """
    linear = chart_image(patch=patch, gap=gap, turns=turns)
    return scanner_response(linear, response=response, gain=gain, noise=noise, bits=bits, seed=seed)
