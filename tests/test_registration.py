"""Registration of examples onto the query, and the coherence it gives the copy (#32)."""

from __future__ import annotations

import numpy as np

from imagemap import Database, Example, colorize
from imagemap.depth.register import (
    example_positions,
    position_frame,
    query_positions,
    register,
)
from imagemap.metrics import fragments


def ellipsoid(shape=(90, 120), centre=(45, 60), radii=(30, 48)):
    yy, xx = np.mgrid[0 : shape[0], 0 : shape[1]].astype(np.float64)
    u = ((yy - centre[0]) / radii[0]) ** 2 + ((xx - centre[1]) / radii[1]) ** 2
    return np.where(u < 1, 0.3 + np.sqrt(np.clip(1 - u, 0, 1)), 0.0).astype(np.float32)


def stripes(depth, period=11.0, phase=0.0):
    """Crisp vertical stripes with a little grain, painted on the object."""
    xx = np.arange(depth.shape[1])[None, :] + phase
    dark = (np.sin(2 * np.pi * xx / period) > 0)[..., None]
    image = np.where(dark, [0.25, 0.15, 0.1], [0.9, 0.7, 0.3])
    grain = 0.03 * np.random.default_rng(0).standard_normal(depth.shape)[..., None]
    return np.clip(image + grain, 0, 1) * (depth > 0)[..., None]


def test_the_warp_carries_the_outline_onto_the_example():
    """An example that is the query moved and stretched: the warp maps the query's tips,
    top and bottom onto the example's (known answer, within 1.5 px)."""
    query = ellipsoid(centre=(45, 60), radii=(30, 48))
    example = ellipsoid(centre=(40, 66), radii=(24, 40))
    warp = register(query, example)
    ys = np.array([45.0, 45.0, 16.0, 74.0])
    xs = np.array([13.0, 107.0, 60.0, 60.0])
    wy, wx = warp.forward(ys, xs)
    expected_y = 40 + (ys - 45) * 24 / 30
    expected_x = 66 + (xs - 60) * 40 / 48
    assert np.max(np.abs(wy - expected_y)) < 1.5 and np.max(np.abs(wx - expected_x)) < 1.5
    # The inverse takes the example's points back.
    qy, qx = warp.inverse(wy, wx)
    np.testing.assert_allclose(np.c_[qy, qx], np.c_[ys, xs], atol=0.5)


def test_depth_units_do_not_change_the_warp():
    query, example = ellipsoid(), ellipsoid(centre=(42, 58), radii=(28, 52))
    a = register(query, example)
    b = register(query * 1000.0, example * 0.001)
    # Float32 rounding only: 1e-3 px of a displacement of tenths of a pixel.
    np.testing.assert_allclose(a.coefficients, b.coefficients, atol=1e-3)


def test_registered_positions_agree_where_the_warp_says():
    """An example pixel's registered position is its query pixel's own position."""
    query, example = ellipsoid(), ellipsoid(centre=(42, 58), radii=(28, 52))
    warp = register(query, example)
    frame = position_frame(query > 0)
    query_levels = query_positions(query.shape, frame, 2)
    example_levels = example_positions(example.shape, warp, frame, 2)
    ey, ex = (int(round(v[0])) for v in warp.forward(np.array([45.0]), np.array([80.0])))
    np.testing.assert_allclose(example_levels[0][ey, ex], query_levels[0][45, 80], atol=0.05)
    assert query_levels[1].shape == (45, 60, 2) and example_levels[1].shape == (45, 60, 2)


def test_a_large_pair_is_registered_from_block_averaged_guides_as_well():
    """At 800x1100 (an object 670 px across) the guides are made from 2x2 block averages
    (detail_size), not at full size; the warp still maps the tips, top and bottom onto
    the example's (known answer, within 3 px: a working pixel is 10 px here), as the
    full-size guides' warp does."""
    from imagemap.depth.config import Registration

    query = ellipsoid((800, 1100), centre=(400, 550), radii=(300, 480))
    example = ellipsoid((800, 1100), centre=(360, 600), radii=(240, 405))
    assert np.sqrt((query > 0).sum()) // Registration().detail_size == 2  # blocks of 2
    ys = np.array([400.0, 400.0, 110.0, 690.0])
    xs = np.array([80.0, 1020.0, 550.0, 550.0])
    for detail in (Registration().detail_size, 1e9):  # blocks, full size
        warp = register(query, example, registration=Registration(detail_size=detail))
        wy, wx = warp.forward(ys, xs)
        assert np.max(np.abs(wy - (360 + (ys - 400) * 240 / 300))) < 3.0
        assert np.max(np.abs(wx - (600 + (xs - 550) * 405 / 480))) < 3.0


def test_a_coarser_position_grid_interpolates_the_same_positions():
    """Positions from a grid of 32 points along the longer side agree with every 4th
    pixel's within a hundredth of the object's radius (the warp is smooth)."""
    query, example = (
        ellipsoid((300, 400), (150, 200), (100, 160)),
        ellipsoid((300, 400), (140, 210), (90, 170)),
    )
    warp = register(query, example)
    frame = position_frame(query > 0)
    (fine,) = example_positions(example.shape, warp, frame, 1)
    (coarse,) = example_positions(example.shape, warp, frame, 1, grid_points=32)
    inside = example > 0
    assert np.max(np.abs(fine[inside] - coarse[inside])) < 0.01


def test_each_example_gets_its_own_position_grid():
    """With ``grid_points``, an example's grid step comes from its own size (known
    answer: the step of its longer side over the points, at least ``grid_step``), not a
    larger example's."""
    query = ellipsoid((300, 400), (150, 200), (100, 160))
    small = ellipsoid((150, 200), (75, 100), (50, 80))
    large = ellipsoid((600, 800), (300, 400), (200, 320))
    frame = position_frame(query > 0)
    for example, step in ((large, 25), (small, 7)):  # ceil(800 / 32), ceil(200 / 32)
        warp = register(query, example)
        (by_points,) = example_positions(example.shape, warp, frame, 1, grid_points=32)
        (by_step,) = example_positions(example.shape, warp, frame, 1, grid_step=step)
        np.testing.assert_array_equal(by_points, by_step)
    (small_grid,) = example_positions(small.shape, register(query, small), frame, 1, 4, 32)
    (large_step,) = example_positions(small.shape, register(query, small), frame, 1, 25)
    assert not np.array_equal(small_grid, large_step)


def test_shifted_copies_of_one_striped_map_give_a_handful_of_fragments():
    """Two examples that are one striped map shifted (each on its own, slightly different
    object) and a query of a third shape: registered, the copy is a couple of whole
    regions that keep the stripes; the paper's method cuts it into more pieces."""
    shapes = [((45, 60), (30, 48)), ((43, 62), (29, 50)), ((46, 58), (31, 46))]
    examples = []
    for i, (centre, radii) in enumerate(shapes[:2]):
        depth = ellipsoid(centre=centre, radii=radii)
        examples.append(Example.from_arrays(f"fish_{i}", depth, stripes(depth, phase=3.0 * i)))
    query = ellipsoid(centre=shapes[2][0], radii=shapes[2][1])
    database = Database(examples)
    ours = colorize(query, database, "fish", seed=0)
    paper = colorize(query, database, "fish", seed=0, finish="paper")
    count = fragments(ours.source, query > 0)
    assert count.count_90 <= 3 and count.mean_share > 0.4, count
    assert fragments(paper.source, query > 0).count_90 > 2 * count.count_90
    # Stripes kept: across the object's middle, each column is mostly one tone.
    lum = ours.image[35:55, 20:100].mean(axis=2)
    dark = lum < 0.45
    assert np.mean(np.abs(dark.mean(axis=0) - 0.5) > 0.35) > 0.8


def test_the_registrations_relief_detail_is_the_full_size_one_or_none():
    """register_with_detail hands on the relief's detail it made where it is the full-size
    relief_detail of the query and every example (the seams' relief channel, not made
    again), and none where the registration averaged blocks (a small detail_size)."""
    from imagemap.depth.config import Registration
    from imagemap.depth.register import register_all, register_with_detail, relief_detail

    query = ellipsoid()
    examples = [ellipsoid(centre=(42, 58), radii=(28, 52)), ellipsoid(radii=(26, 44))]
    registered = register_with_detail(query, examples)
    assert registered.detail is not None
    query_detail, example_details = registered.detail
    assert np.array_equal(query_detail, relief_detail(query, query > 0, 0.03))
    for detail, example in zip(example_details, examples, strict=True):
        assert np.array_equal(detail, relief_detail(example, example > 0, 0.03))
    warps = register_all(query, examples)
    assert all(
        np.array_equal(a.coefficients, b.coefficients)
        and np.array_equal(a.relief_residual, b.relief_residual)
        for a, b in zip(warps, registered.warps, strict=True)
    )
    coarse = register_with_detail(query, examples, registration=Registration(detail_size=16.0))
    assert coarse.detail is None


def test_the_warp_on_a_grid_is_the_warp_at_its_points():
    """forward_grid gives forward's very values at every point of a grid of rows and
    columns (a fitted warp, points past the control grid's box included)."""
    query, example = ellipsoid(), ellipsoid(centre=(40, 66), radii=(24, 40))
    warp = register(query, example)
    ys = np.arange(-3.0, 95.0) * 1.01
    xs = (np.arange(125.0) + 0.5) * 0.97 - 0.5
    gy, gx = np.meshgrid(ys, xs, indexing="ij")
    for grid, points in zip(warp.forward_grid(ys, xs), warp.forward(gy, gx), strict=True):
        assert np.array_equal(grid, points)


def test_the_displacement_is_the_sum_of_its_sixteen_terms():
    """Warp.displacement, with its buffers, gives the bytes of the B-spline sum written
    out: per point, 16 terms (weight_y * weight_x) * coefficient added in order."""
    from imagemap.depth.register import Warp, _span

    rng = np.random.default_rng(11)
    n = 5
    warp = Warp(np.array([30.0, 40.0]), np.array([28.0, 36.0]), np.eye(2),
                (-3.0, 70.0, -5.0, 90.0), rng.normal(size=(2, n * n)), n)  # fmt: skip
    ys, xs = rng.uniform(-20, 90, (31, 17)), rng.uniform(-20, 110, (31, 17))
    first_y, weights_y = _span(ys.ravel(), -3.0, 70.0, n)
    first_x, weights_x = _span(xs.ravel(), -5.0, 90.0, n)
    dy, dx = np.zeros(ys.size), np.zeros(ys.size)
    for a in range(4):
        for b in range(4):
            weight = weights_y[:, a] * weights_x[:, b]
            index = (first_y + a) * n + first_x + b
            dy = dy + weight * warp.coefficients[0, index]
            dx = dx + weight * warp.coefficients[1, index]
    found = warp.displacement(ys, xs)
    assert np.array_equal(found[0], dy.reshape(ys.shape))
    assert np.array_equal(found[1], dx.reshape(ys.shape))


def test_a_position_grid_on_a_level_is_its_interpolation_at_the_levels_pixels():
    """_on_level gives the bytes of map_coordinates at each level's pixel centres divided
    by the step: by SciPy's zoom and shift for a step that is a power of two (every
    coordinate exact), by map_coordinates itself for another step."""
    from scipy import ndimage

    from imagemap.depth.register import _level_coordinates, _on_level

    rng = np.random.default_rng(5)
    for step in (1, 2, 3, 4, 5, 8, 16):
        for shape in ((97, 130), (64, 64), (5, 301)):
            grid_shape = (
                len(range(0, shape[0] + step, step)),
                len(range(0, shape[1] + step, step)),
            )
            grid = np.cumsum(rng.normal(size=grid_shape), axis=1) * 10.0 ** rng.uniform(-3, 3)
            for level in range(4):
                ys, xs = _level_coordinates(shape, level)
                gy, gx = np.meshgrid(ys / step, xs / step, indexing="ij")
                expected = ndimage.map_coordinates(grid, [gy, gx], order=1, mode="nearest")
                found = _on_level(grid, shape, level, step)
                assert found.dtype == expected.dtype
                assert np.array_equal(found, expected)


def test_the_guide_made_where_the_zoom_reads_it_zooms_to_the_whole_guides_values():
    """_guide_and_nearest gives the guide of SciPy's distance transforms written out
    (the whole map, and the nearest pixels its outside distance came from); made only at
    the rows and columns _zoom_reads names, its zoom to the working size is the same."""
    from scipy import ndimage

    from imagemap.depth.register import OUTLINE_REACH, _guide_and_nearest, _zoom_reads

    rng = np.random.default_rng(8)
    for shape, noisy, scale in (((90, 120), False, 0.2), ((131, 77), True, 0.53),
                                ((64, 64), False, 0.999), ((200, 150), True, 0.07)):  # fmt: skip
        depth = ellipsoid(shape, (shape[0] * 0.45, shape[1] * 0.55), (shape[0] / 3, shape[1] / 3))
        mask = depth > 0
        if noisy:  # holes, and specks outside
            mask ^= rng.random(shape) < 0.05
            depth = np.where(mask, depth + 0.3, 0.0).astype(np.float32)
        size = float(np.sqrt(mask.sum()))
        outside, (iy, ix) = ndimage.distance_transform_edt(~mask, return_indices=True)
        signed = ndimage.distance_transform_edt(mask) - outside
        relief = np.where(mask, depth / float(depth[mask].max()), 0.0)
        smooth = ndimage.gaussian_filter(relief, 0.05 * size)
        detail = np.where(mask, relief - smooth, 0.0)
        unit = float(np.percentile(np.abs(detail[mask]), 95))
        expected = 0.5 * np.tanh(signed / (OUTLINE_REACH * size)) + 0.5 * relief
        expected = (expected + 0.3 * np.tanh(detail / unit)).astype(np.float32)
        guide, nearest = _guide_and_nearest(depth, mask, 0.3, 0.05)
        assert np.array_equal(guide, expected)
        assert np.array_equal(nearest, np.stack([iy, ix]))
        reads = _zoom_reads(shape, scale)
        assert sum(map(len, reads)) < sum(shape) or scale > 0.5  # fewer pixels made
        part, _ = _guide_and_nearest(depth, mask, 0.3, 0.05, reads)
        zoomed = ndimage.zoom(part, scale, order=1, prefilter=False)
        assert np.array_equal(zoomed, ndimage.zoom(expected, scale, order=1, prefilter=False))


def test_the_inverse_is_every_points_twelve_steps_to_the_bit():
    """Warp.inverse leaves a point once it is a fixed point to the bit: the same values as
    twelve fixed-point steps of every point (the reference, written out here)."""
    query, example = ellipsoid(), ellipsoid(centre=(40, 66), radii=(24, 40))
    warp = register(query, example)
    ys, xs = np.meshgrid(np.arange(-4.0, 95.0, 1.5), np.arange(-4.0, 125.0, 1.5), indexing="ij")
    inverse = np.linalg.inv(warp.linear)
    oy, ox = ys - warp.example_centre[0], xs - warp.example_centre[1]
    ty = warp.query_centre[0] + inverse[0, 0] * oy + inverse[0, 1] * ox
    tx = warp.query_centre[1] + inverse[1, 0] * oy + inverse[1, 1] * ox
    qy, qx = ty.copy(), tx.copy()
    for _ in range(12):
        dy, dx = warp.displacement(qy, qx)
        qy, qx = ty - dy, tx - dx
    iy, ix = warp.inverse(ys, xs)
    assert iy.shape == ys.shape
    np.testing.assert_array_equal(iy, qy)
    np.testing.assert_array_equal(ix, qx)


def test_the_registrations_nearest_pixels_are_the_bands_own_or_none():
    """register_with_detail hands on, when asked, the query's and each example's nearest
    object pixels where it made its guide from the full-size mask: the very indices the
    bands' fills would make (nearest_object_pixels); none where it averaged blocks."""
    from imagemap.core.blend import nearest_object_pixels
    from imagemap.depth.config import Registration
    from imagemap.depth.register import register_with_detail

    query = ellipsoid()
    examples = [ellipsoid(centre=(42, 58), radii=(28, 52)), ellipsoid(radii=(26, 44))]
    assert register_with_detail(query, examples).nearest == [None, None, None]  # not asked
    registered = register_with_detail(query, examples, keep_nearest=True)
    assert len(registered.nearest) == 3
    for nearest, depth in zip(registered.nearest, [query, *examples], strict=True):
        assert nearest is not None
        np.testing.assert_array_equal(nearest, nearest_object_pixels(depth > 0))
    blocks = register_with_detail(
        query, examples, registration=Registration(detail_size=16.0), keep_nearest=True
    )
    assert blocks.nearest == [None, None, None]


def test_the_examples_on_threads_give_the_one_at_a_time_bytes(monkeypatch):
    """The registration, the bands and the small features of each example on the kernels'
    threads (schedule.each_example) give the very map, sources and costs of one example at a
    time (the reference: the frames below THREADED_MIN_PIXELS)."""
    from imagemap.depth import schedule

    examples = []
    for i, (centre, radii) in enumerate([((45, 60), (30, 48)), ((43, 62), (29, 50))]):
        depth = ellipsoid(centre=centre, radii=radii)
        examples.append(Example.from_arrays(f"fish_{i}", depth, stripes(depth, phase=3.0 * i)))
    query = ellipsoid(centre=(46, 58), radii=(31, 46))
    database = Database(examples)
    runs = []
    for least in (2**40, 0):  # one at a time, then on the threads
        monkeypatch.setattr(schedule, "THREADED_MIN_PIXELS", least)
        runs.append(colorize(query, database, "fish", seed=0))
    one, threaded = runs
    for a, b in ((one.image, threaded.image), (one.source, threaded.source)):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(one.cost, threaded.cost)
