"""Normals from height maps, normal-map encoding, shading, relief views and preview sheets."""

import numpy as np
import pytest

from imagemap.io import InputError
from imagemap.render import (
    decode_normal_map,
    direction_from_angles,
    encode_normal_map,
    normals_from_depth,
    normals_from_height,
    preview_pair,
    relief_view,
    shade,
)


def test_flat_plane_lambert_equals_analytic_value():
    normals = normals_from_height(np.zeros((16, 16)))
    albedo = np.full((16, 16, 3), (0.8, 0.5, 0.2), np.float32)
    light = direction_from_angles(elevation=30.0, azimuth=40.0)
    image = shade(normals, albedo, light=light, model="lambert", light_intensity=0.9)
    # n = (0, 0, 1): n.l = sin(elevation) = 0.5.
    np.testing.assert_allclose(image, 0.9 * 0.5 * albedo, atol=1e-6)


def test_tilted_plane_normal_and_lambert_cosine():
    slope = 0.5
    ramp = np.add.outer(np.zeros(12), slope * np.arange(12.0))  # rises to the right
    normals = normals_from_height(ramp)
    expected = np.array([-slope, 0.0, 1.0]) / np.hypot(slope, 1.0)
    np.testing.assert_allclose(normals[5, 5], expected, atol=1e-6)
    image = shade(normals, 1.0, light=(0, 0, 1))
    np.testing.assert_allclose(image[5, 5], 1.0 / np.hypot(slope, 1.0), atol=1e-6)


def test_height_rising_up_the_screen_faces_down_the_screen():
    ramp = np.add.outer(-np.arange(10.0), np.zeros(10))  # higher towards row 0 (y up)
    normal = normals_from_height(ramp)[5, 5]
    np.testing.assert_allclose(normal, np.array([0.0, -1.0, 1.0]) / np.sqrt(2), atol=1e-6)


def test_light_behind_the_surface_gives_black_and_blinn_phong_adds_highlight():
    flat = normals_from_height(np.zeros((4, 4)))
    assert np.all(shade(flat, 1.0, light=(0, 0, -1)) == 0)
    matte = shade(flat, 0.5, light=(0, 0, 1))
    glossy = shade(flat, 0.5, light=(0, 0, 1), model="blinn_phong", specular=0.3)
    np.testing.assert_allclose(glossy - matte, 0.3, atol=1e-6)  # n = h: highlight peak


def test_normal_map_rgb_round_trip_through_8_bits():
    rng = np.random.default_rng(0)
    normals = normals_from_height(rng.standard_normal((32, 32)), scale=1.5)
    encoded = encode_normal_map(normals)
    assert encoded.min() >= 0 and encoded.max() <= 1
    np.testing.assert_allclose(encode_normal_map(np.array([0.0, 0.0, 1.0])), [0.5, 0.5, 1.0])
    np.testing.assert_allclose(decode_normal_map(encoded), normals, atol=1e-6)
    quantized = np.round(encoded * 255).astype(np.uint8)
    decoded = decode_normal_map(quantized)
    angle = np.degrees(np.arccos(np.clip((decoded * normals).sum(-1), -1, 1)))
    assert angle.max() < 0.5


def test_depth_normals_ignore_the_silhouette_cliff():
    depth = np.zeros((20, 20), np.float32)
    depth[5:15, 5:15] = 0.7  # a flat plateau: its rim must stay flat
    normals = normals_from_depth(depth)
    np.testing.assert_allclose(normals[5:15, 5:15].reshape(-1, 3)[:, 2], 1.0, atol=1e-6)
    # Without the fill, the rim would face outwards: check the naive differences do.
    assert normals_from_height(depth, scale=5.0)[5, 10, 2] < 0.5


def test_relief_view_front_view_keeps_the_map_upright_and_unshaded():
    depth = np.full((24, 24), 0.5, np.float32)
    image = np.zeros((24, 24, 3), np.float32)
    image[:12, :12] = (1, 0, 0)  # top left red
    image[:12, 12:] = (0, 1, 0)  # top right green
    image[12:, :, 2] = 1  # bottom blue
    front = relief_view(depth, image, tilt=0.0, turn=0.0, light=(0, 0, 1), ambient=0.0)
    # Flat, lit and seen from the front: the map itself (fitted to 92% of the canvas).
    np.testing.assert_allclose(front[6, 6], (1, 0, 0), atol=1e-6)
    np.testing.assert_allclose(front[6, 17], (0, 1, 0), atol=1e-6)
    np.testing.assert_allclose(front[18, 12], (0, 0, 1), atol=1e-6)


def test_relief_view_tilted_shows_the_near_rim_lower_and_hides_nothing_flat():
    depth = np.zeros((40, 40), np.float32)
    depth[10:30, 10:30] = 1.0
    image = np.ones((40, 40, 3), np.float32)
    view = relief_view(depth, image, tilt=40.0, turn=0.0, light=(0, 0, 1), ambient=0.0)
    covered = np.abs(view - np.array([0.82, 0.82, 0.84])).sum(-1) > 1e-3
    rows = np.nonzero(covered.any(axis=1))[0]
    # Tipping back foreshortens the square: fewer rows than columns, and no holes inside.
    assert len(rows) < np.nonzero(covered.any(axis=0))[0].size
    assert covered[rows.min() + 2 : rows.max() - 2, 20].all()


def test_preview_pair_layout_and_uncovered_reference_in_red():
    depth = np.zeros((32, 40), np.float32)
    depth[6:26, 8:32] = 0.6
    synthesized = np.full((32, 40, 3), 0.5, np.float32)
    reference = np.full((16, 20, 3), 0.5, np.float32)  # other shape: resized
    covered = np.ones((32, 40), bool)
    covered[:, :20] = False
    sheet = preview_pair(depth, synthesized, reference, reference_mask=covered, gutter=4)
    assert sheet.shape == (2 * 32 + 12, 2 * 40 + 12, 3)
    right_front = sheet[4 : 4 + 32, 48 : 48 + 40]
    red = (right_front[..., 0] > 0.5) & (right_front[..., 1] < 0.05)
    assert red[10:20, 10:18].all() and not red[10:20, 22:30].any()


def test_bad_inputs_are_named():
    with pytest.raises(InputError, match="albedo"):
        shade(np.zeros((4, 4, 3)), np.zeros((5, 5, 3)))
    with pytest.raises(InputError, match="model"):
        shade(np.zeros((4, 4, 3)), 1.0, model="phong")
    with pytest.raises(InputError, match="light"):
        shade(np.zeros((4, 4, 3)), 1.0, light=(0, 0, 0))
