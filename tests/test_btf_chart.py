"""The scanner response (Table 1's model) fitted from a synthetic ColorChecker scan."""

from __future__ import annotations

import numpy as np
import pytest

from data_gen.chart import chart_image, scan_chart
from imagemap.btf.constraints import ScannerResponse, color_correct
from imagemap.btf.response import (
    chart_patch_values,
    colorchecker_linear,
    fit_chart_response,
    fit_scanner_response,
)
from imagemap.io import InputError

TRUTH = ScannerResponse((0.02, 0.0, 0.01), (1.25, 1.1, 0.95), (1.6, 1.8, 2.05))


def test_chart_patches_are_the_standard_values():
    np.testing.assert_allclose(chart_patch_values(chart_image()), colorchecker_linear(), atol=1e-6)
    # White patch of the standard chart: sRGB (243, 243, 242) is linear 0.896.
    assert colorchecker_linear()[18, 0] == pytest.approx(0.8963, abs=1e-3)


@pytest.mark.parametrize("turns", [0, 1, 2, 3])
def test_fit_recovers_known_response_from_a_noisy_turned_scan(turns):
    scan = scan_chart(TRUTH, noise=0.005, turns=turns, gap=4, seed=turns)
    fit = fit_chart_response(scan)
    assert (fit.turns + turns) % 4 == 0
    np.testing.assert_allclose(fit.response.offsets, TRUTH.offsets, atol=0.004)
    np.testing.assert_allclose(fit.response.multipliers, TRUTH.multipliers, rtol=0.01)
    np.testing.assert_allclose(fit.response.gammas, TRUTH.gammas, rtol=0.01)
    grid = np.repeat(np.linspace(0.05, 1, 64, dtype=np.float32)[None, :, None], 3, axis=2)
    error = np.abs(color_correct(grid, response=fit.response) - color_correct(grid, response=TRUTH))
    assert error.max() < 0.003
    assert max(fit.rms_scan_error) < 0.002


def test_fit_without_noise_is_exact():
    patches = chart_patch_values(scan_chart(TRUTH, bits=None))
    fit = fit_scanner_response(patches, colorchecker_linear())
    np.testing.assert_allclose(fit.response.gammas, TRUTH.gammas, atol=1e-4)
    np.testing.assert_allclose(fit.response.offsets, TRUTH.offsets, atol=1e-4)


def test_not_a_chart_is_refused():
    rng = np.random.default_rng(0)
    with pytest.raises(InputError, match="ColorChecker"):
        fit_chart_response(rng.random((60, 90, 3)))
    with pytest.raises(InputError, match="hardly varies"):
        fit_chart_response(np.full((60, 90, 3), 0.5))
    with pytest.raises(InputError, match="too small"):
        fit_chart_response(np.zeros((4, 6, 3)))
