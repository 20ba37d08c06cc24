import numpy as np
import pytest

from imagemap.core.engine import EngineParams, Mapping, uniform_levels
from imagemap.core.pyramid import (
    collapse_laplacian,
    gaussian_pyramid,
    laplacian_pyramid,
    level_shapes,
    mask_pyramid,
)
from imagemap.core.solver import LevelSolver, Timer


@pytest.mark.parametrize("shape", [(150, 200), (37, 50, 3), (64, 64, 5), (33, 17)])
def test_laplacian_round_trip_is_exact(shape):
    x = np.random.default_rng(0).random(shape).astype(np.float32)
    pyramid = laplacian_pyramid(x, 4)
    assert [p.shape[:2] for p in pyramid] == level_shapes(shape[:2], 4)
    np.testing.assert_allclose(collapse_laplacian(pyramid), x, atol=2e-6)


@pytest.mark.parametrize("shape", [(1, 7), (5, 1), (3, 3), (9, 5, 2)])
def test_laplacian_round_trip_down_to_one_pixel(shape):
    # Odd sizes whose coarse levels shrink to a single row, column or pixel.
    x = np.random.default_rng(1).random(shape).astype(np.float32)
    pyramid = laplacian_pyramid(x, 4)
    assert pyramid[-1].shape[:2] == level_shapes(shape[:2], 4)[-1]
    np.testing.assert_allclose(collapse_laplacian(pyramid), x, atol=2e-6)


def test_constant_image_has_no_detail_bands():
    # A flat image is all residual: any border error in reduce/expand would show as detail.
    pyramid = laplacian_pyramid(np.full((37, 51, 3), 0.4, np.float32), 3)
    for band in pyramid[:-1]:
        np.testing.assert_allclose(band, 0.0, atol=1e-6)
    np.testing.assert_allclose(pyramid[-1], 0.4, atol=1e-6)


def test_gaussian_levels_sample_even_pixels():
    # Coarse pixel (y, x) sits on fine pixel (2y, 2x): a smooth ramp shows it.
    yy, xx = np.mgrid[0:40, 0:40].astype(np.float32)
    ramp = 3 * yy + xx
    coarse = gaussian_pyramid(ramp, 2)[1]
    np.testing.assert_allclose(coarse[5:15, 5:15], ramp[10:30:2, 10:30:2], atol=1e-3)


def test_mask_pyramid_keeps_area():
    mask = np.zeros((64, 64), bool)
    mask[10:50, 20:40] = True
    coarse = mask_pyramid(mask, 3)
    assert coarse[2].sum() == pytest.approx(mask.sum() / 16, rel=0.15)


def test_source_coordinates_propagate_times_two():
    """Coarse source (e, y, x) becomes (e, 2y + dy, 2x + dx) at the finer level."""
    rng = np.random.default_rng(0)
    fine = Mapping(guide=rng.random((20, 24, 1)), appearance=rng.random((20, 24, 1)))
    exemplars = [fine, Mapping(guide=rng.random((18, 22, 1)), appearance=rng.random((18, 22, 1)))]
    query = Mapping(guide=rng.random((16, 16, 1)))
    params = EngineParams(levels=uniform_levels((3,)), backend="exact")
    solver = LevelSolver(query, exemplars, 3, params, rng, Timer())
    coarse = np.zeros((8, 8, 3), dtype=np.int32)
    coarse[..., 0] = 1
    coarse[..., 1] = np.arange(8)[:, None]
    coarse[..., 2] = np.arange(8)[None, :] + 1
    matches = solver.propagate(coarse)
    y, x = solver.query_y, solver.query_x
    assert np.all(solver.cand_e[matches] == 1)
    np.testing.assert_array_equal(solver.cand_y[matches], 2 * (y // 2) + y % 2)
    np.testing.assert_array_equal(solver.cand_x[matches], np.minimum(2 * (x // 2 + 1) + x % 2, 21))


def test_reduce_is_the_whole_gaussian_filter_subsampled():
    """reduce filters the columns only on the rows it keeps: the values of ndimage's
    whole-image gaussian_filter taken at every second pixel, grey or colour, odd sizes."""
    from scipy import ndimage

    from imagemap.core.pyramid import reduce

    rng = np.random.default_rng(7)
    for shape, sigma in [((31, 45), (1.0, 1.0)), ((20, 17, 3), (1.0, 1.0, 0.0))]:
        image = rng.random(shape).astype(np.float32)
        smooth = ndimage.gaussian_filter(image, sigma, mode="reflect")
        assert np.array_equal(reduce(image), smooth[::2, ::2])


def test_laplacian_bands_of_one_pyramid_are_the_laplacian_pyramids():
    from imagemap.core.pyramid import gaussian_pyramid, laplacian_bands, laplacian_pyramid

    image = np.random.default_rng(8).random((41, 30)).astype(np.float32)
    bands = laplacian_bands(gaussian_pyramid(image, 4))
    expected = laplacian_pyramid(image, 4)[:3]
    assert all(np.array_equal(a, b) for a, b in zip(bands, expected, strict=True))
