"""Photometric stereo, Frankot-Chellappa integration and seamless range-map tiling."""

import numpy as np
import pytest
from scipy import ndimage

from imagemap.btf.photometric import (
    crossfade_tile,
    enlarge_range_map,
    frankot_chellappa,
    periodic_component,
    photometric_stereo,
)
from imagemap.io import InputError
from imagemap.render import direction_from_angles, normals_from_height


def _lambertian_scene(shadows: bool):
    rng = np.random.default_rng(3)
    height = ndimage.gaussian_filter(rng.standard_normal((48, 64)), 3.5)
    height *= (1.2 if shadows else 0.6) / np.abs(np.gradient(height)).max()  # max slope
    normals = normals_from_height(height)
    albedo = 0.3 + 0.5 * ndimage.gaussian_filter(rng.random((48, 64, 3)), (3, 3, 0))
    elevations = (20, 50) if shadows else (40, 65)
    lights = np.stack([direction_from_angles(e, a) for e in elevations for a in range(0, 360, 45)])
    images = albedo[None] * np.clip(np.einsum("hwc,nc->nhw", normals, lights), 0, None)[..., None]
    return height, normals, albedo, lights, images.astype(np.float32)


def _angle_degrees(a, b):
    return np.degrees(np.arccos(np.clip((a * b).sum(-1), -1.0, 1.0)))


def test_photometric_stereo_recovers_normals_albedo_and_heights():
    height, normals, albedo, lights, images = _lambertian_scene(shadows=False)
    found_normals, found_albedo = photometric_stereo(images, lights)
    angle = _angle_degrees(found_normals, normals)
    assert angle.mean() < 0.1 and angle.max() < 0.5
    np.testing.assert_allclose(found_albedo, albedo, atol=1e-3)
    found_height = frankot_chellappa(found_normals)
    error = (found_height - found_height.mean()) - (height - height.mean())
    # Up to an offset: RMS under 1% of the relief, worst texel under 3%.
    assert np.sqrt((error**2).mean()) < 0.01 * np.ptp(height)
    assert np.abs(error).max() < 0.03 * np.ptp(height)


def test_mirror_extension_beats_periodic_integration_of_a_non_periodic_field():
    height, normals, *_ = _lambertian_scene(shadows=False)
    errors = {}
    for mirror in (True, False):
        found = frankot_chellappa(normals, mirror=mirror)
        errors[mirror] = np.sqrt((((found - found.mean()) - (height - height.mean())) ** 2).mean())
    assert errors[True] < 0.2 * errors[False]


def test_shadowed_samples_are_left_out_of_the_fit():
    _, normals, _, lights, images = _lambertian_scene(shadows=True)
    assert (images[..., 0] == 0).mean() > 0.01  # attached shadows present
    naive, _ = photometric_stereo(images, lights, min_intensity=-1.0)  # keeps black samples
    robust, _ = photometric_stereo(images, lights)  # default: drops samples <= 0
    assert _angle_degrees(robust, normals).max() < 0.5
    assert _angle_degrees(naive, normals).max() > 2.0


def test_seamless_tiles_wrap_without_jumps():
    rng = np.random.default_rng(0)
    height = ndimage.gaussian_filter(rng.standard_normal((40, 40)), 3) + np.arange(40) * 0.05
    raw_seam = np.abs(height[:, 0] - height[:, -1]).max()
    assert np.abs(periodic_component(height)[:, 0] - periodic_component(height)[:, -1]).max() < (
        0.1 * raw_seam
    )
    tile = crossfade_tile(height)
    for axis_tile in (tile, tile.T):
        seam = np.abs(axis_tile[:, 0] - axis_tile[:, -1]).max()
        assert seam <= np.abs(np.diff(axis_tile, axis=1)).max()
    assert tile.shape == (30, 30)
    # Slopes also continue across the wrap (no crease): second difference like inside.
    wrapped = np.concatenate([tile[:, -2:], tile[:, :2]], axis=1)
    assert np.abs(np.diff(wrapped, 2, axis=1)).max() <= 1.5 * np.abs(np.diff(tile, 2, axis=1)).max()


def test_enlarge_range_map_any_size_seeded():
    height = np.random.default_rng(0).random((16, 16)).astype(np.float32)
    a = enlarge_range_map(height, (50, 37), seed=4)
    b = enlarge_range_map(height, (50, 37), seed=4)
    assert a.shape == (50, 37) and a.tobytes() == b.tobytes()
    tile = crossfade_tile(height)
    np.testing.assert_array_equal(a[:12, :12], a[12:24, 12:24])  # period = tile side
    assert tile.shape == (12, 12)


def test_bad_inputs_are_named():
    with pytest.raises(InputError, match="light_dirs"):
        photometric_stereo(np.zeros((3, 4, 4)), np.zeros((2, 3)))
    with pytest.raises(InputError, match="horizon"):
        photometric_stereo(np.zeros((3, 4, 4)), np.array([[0, 0, 1.0], [1, 0, 0], [0, 1, -1]]))
