"""Procedural textures: ranges, determinism, smoothness and known values."""

from __future__ import annotations

import numpy as np
import pytest

from data_gen.procedural import (
    color_ramp,
    fbm,
    marble,
    perlin,
    spots,
    stripes,
    turbulence,
    wood,
    worley,
)
from imagemap.io import InputError


@pytest.fixture
def points3() -> np.ndarray:
    return np.random.default_rng(7).uniform(-3, 3, size=(4000, 3)).astype(np.float32)


@pytest.fixture
def grid2() -> np.ndarray:
    yy, xx = np.mgrid[0:64, 0:64] / 16.0
    return np.stack([xx, yy], axis=-1)


def test_perlin_is_zero_on_lattice_and_bounded(points3):
    lattice = np.array([[0, 0, 0], [1, 2, 3], [-4, 5, 7]], dtype=np.float32)
    assert np.allclose(perlin(lattice, seed=3), 0.0, atol=1e-6)
    values = perlin(points3, seed=3, frequency=2.0)
    assert values.dtype == np.float32 and values.shape == (4000,)
    assert values.min() >= -1 and values.max() <= 1
    assert 0.1 < values.std() < 0.6  # not degenerate


def test_perlin_is_continuous(grid2):
    # Neighbouring samples 1/64 of a cell apart differ far less than the value range.
    fine = np.stack(np.meshgrid(np.linspace(0, 4, 257), np.linspace(0, 4, 257)), -1)
    values = perlin(fine, seed=1)
    assert np.abs(np.diff(values, axis=0)).max() < 0.1
    assert np.abs(np.diff(values, axis=1)).max() < 0.1


def test_seed_determinism_and_difference(grid2):
    a = fbm(grid2, octaves=5, seed=11)
    b = fbm(grid2, octaves=5, seed=11)
    c = fbm(grid2, octaves=5, seed=12)
    assert a.tobytes() == b.tobytes()
    assert np.abs(a - c).mean() > 0.05
    # A Generator seed draws the tables from the caller's stream: same stream, same bytes.
    g1 = fbm(grid2, seed=np.random.default_rng(5))
    g2 = fbm(grid2, seed=np.random.default_rng(5))
    assert g1.tobytes() == g2.tobytes()


def test_persistence_controls_roughness(grid2):
    smooth = fbm(grid2, octaves=6, persistence=0.2, seed=2, frequency=2.0)
    rough = fbm(grid2, octaves=6, persistence=0.9, seed=2, frequency=2.0)

    def roughness(v):
        return np.abs(np.diff(v, axis=1)).mean() / v.std()

    assert roughness(rough) > 1.5 * roughness(smooth)


def test_ranges_of_patterns(points3, grid2):
    for values in (
        turbulence(points3, seed=1),
        marble(points3, seed=1),
        wood(points3, seed=1),
        stripes(points3, warp=0.3, seed=1),
        spots(points3, seed=1),
        stripes(grid2, direction=(0, 1)),
    ):
        assert values.dtype == np.float32
        assert values.min() >= 0.0 and values.max() <= 1.0


def test_wood_rings_follow_distance_to_axis():
    # Without noise, points at radius r on the z axis have ring phase frac(f * r).
    radius = np.array([0.05, 0.3, 0.55, 1.0], dtype=np.float32)
    points = np.stack([radius, np.zeros(4), np.linspace(-2, 2, 4)], axis=-1)
    phase = wood(points, ring_frequency=2.0, amplitude=0.0)
    assert np.allclose(phase, np.mod(2.0 * radius, 1.0), atol=1e-5)


def test_stripes_known_values():
    x = np.array([[0.125, 0.0], [0.375, 0.0], [0.0, 0.0]], dtype=np.float32)
    values = stripes(x, direction=(1, 0), frequency=2.0)
    assert np.allclose(values, [1.0, 0.0, 0.5], atol=1e-5)


def test_worley_distance_is_a_nearest_feature_distance(points3):
    distance = worley(points3, seed=4, frequency=1.5)
    assert distance.min() >= 0 and distance.max() <= np.sqrt(3)
    coverage = spots(points3, frequency=1.5, radius=0.3, softness=1e-6, seed=4)
    assert np.array_equal(coverage > 0.5, distance < 0.3)


def test_color_ramp_interpolates():
    colors = color_ramp(np.array([0.0, 0.25, 1.0, 2.0]), [(0, 0, 0), (1, 0.5, 0)])
    assert np.allclose(colors, [[0, 0, 0], [0.25, 0.125, 0], [1, 0.5, 0], [1, 0.5, 0]])


def test_bad_points_raise():
    with pytest.raises(InputError, match="points"):
        perlin(np.zeros((5, 4)))
    with pytest.raises(InputError, match="direction"):
        marble(np.zeros((5, 3)), direction=(0, 0, 0))
