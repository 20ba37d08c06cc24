"""Scans that register themselves: quarter turns, small rotations and shifts undone."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage
from skimage.registration import phase_cross_correlation
from skimage.transform import rotate

from imagemap.btf.orientation import orient_to_sample
from imagemap.btf.registration import register_scans
from imagemap.io import InputError

SIZE, CROP = 160, 112


def _constraint_images(name: str) -> list[np.ndarray]:
    """The material's four top-view images, light theta 22 at azimuths 0..270."""
    from imagemap.btf.materials import make_material
    from imagemap.btf.rendering import render_btf_matrix

    material = make_material(name, size=SIZE, seed=2)
    lights = np.array([[22.0, a] for a in (0, 90, 180, 270)], np.float32)
    matrix = render_btf_matrix(material, lights, np.array([[0.0, 0.0]], np.float32))
    return [matrix[3 * i : 3 * i + 3].reshape(3, SIZE, SIZE).transpose(1, 2, 0) for i in range(4)]


def _scans(images, order, angles, shifts):
    """Scans under a lamp fixed at the scanner's azimuth 0: the sample turned by a quarter
    turn per azimuth step (rot90 turns directions by -90), then rotated and shifted a
    little, then cropped to the same window."""
    c = (SIZE - CROP) // 2
    scans = []
    for azimuth, angle, shift in zip(order, angles, shifts, strict=True):
        image = np.rot90(images[azimuth], azimuth)
        image = rotate(image, angle, order=3, mode="reflect")  # counter-clockwise
        image = ndimage.shift(image, (*shift, 0), order=3, mode="reflect")
        scans.append(np.clip(0.9 * image[c : c + CROP, c : c + CROP], 0, 1).astype(np.float32))
    return scans


@pytest.fixture(scope="module")
def cloth():
    return _constraint_images("cloth")


@pytest.mark.parametrize("material", ["cloth", "leather"])
def test_turns_rotations_and_shifts_of_shuffled_scans_are_undone(material, cloth):
    images = cloth if material == "cloth" else _constraint_images(material)
    order = [2, 0, 3, 1]  # the reference (first scan) is lit from azimuth 180
    angles = [0.0, 3.0, -2.5, 1.5]
    shifts = [(0.0, 0.0), (-2.5, 4.0), (3.0, -1.5), (1.0, 3.5)]
    reg = register_scans(_scans(images, order, angles, shifts), max_rotation=5.0)
    # Azimuths relative to the reference's: (a - a_ref) mod 360.
    assert reg.azimuths == tuple(float((a - order[0]) % 4 * 90) for a in order)
    # skimage's rotate turns counter-clockwise; the correction turns clockwise.
    np.testing.assert_allclose(reg.angles, angles, atol=0.4)
    top, left, height, width = reg.crop
    c = (SIZE - CROP) // 2
    for azimuth_step, got in enumerate(reg.images):
        want = np.rot90(images[(order[0] + azimuth_step) % 4], order[0])
        want = 0.9 * want[c : c + CROP, c : c + CROP][top : top + height, left : left + width]
        assert got.shape == want.shape
        residual, _, _ = phase_cross_correlation(want.mean(2), got.mean(2), upsample_factor=20)
        assert np.abs(residual).max() <= 0.5, (azimuth_step, residual)
        assert np.linalg.norm(got - want) / np.linalg.norm(want) < 0.12


def test_aligned_scans_in_order_come_back_unchanged(cloth):
    scans = _scans(cloth, [0, 1, 2, 3], [0.0] * 4, [(0.0, 0.0)] * 4)
    reg = register_scans(scans, max_rotation=0)
    assert reg.order == (0, 1, 2, 3) and reg.turns == (0, 1, 2, 3)
    assert np.abs(np.array(reg.shifts)).max() < 0.1
    top, left, height, width = reg.crop
    assert all(got.shape == (height, width, 3) for got in reg.images)
    np.testing.assert_allclose(
        reg.images[0], scans[0][top : top + height, left : left + width], atol=1e-4
    )


def test_mirrored_scanner_convention_swaps_90_and_270(cloth):
    scans = _scans(cloth, [0, 1, 2, 3], [0.0] * 4, [(0.0, 0.0)] * 4)
    reg = register_scans(scans, max_rotation=0, turn_direction=-1)
    assert reg.azimuths == (0.0, 270.0, 180.0, 90.0)


def test_four_copies_of_one_scan_are_refused(cloth):
    scan = _scans(cloth, [0], [0.0], [(0.0, 0.0)])[0]
    with pytest.raises(InputError, match="quarter turns"):
        register_scans([scan] * 4, max_rotation=0)
    with pytest.raises(InputError, match="four scans"):
        register_scans([scan] * 3)
    with pytest.raises(InputError, match="max_rotation"):
        register_scans([scan] * 4, max_rotation=float("nan"))


def test_the_sample_tells_which_scan_is_which_on_an_anisotropic_material():
    from imagemap.btf import compress
    from imagemap.btf.extrapolate import constraint_images
    from imagemap.btf.materials import make_material
    from imagemap.btf.rendering import render_btf_matrix

    lights = np.array([[0, 0], [22, 0], [22, 90], [22, 180], [22, 270]], np.float32)
    views = np.array([[0, 0]], np.float32)
    matrix = render_btf_matrix(make_material("wood", size=96, seed=1), lights, views)
    reference = compress(matrix, shape=(96, 96), light_dirs=lights, view_dirs=views, k=12)
    cols = (np.arange(32, 64)[:, None] * 96 + np.arange(32, 64)).ravel()
    sample = compress(matrix[:, cols], shape=(32, 32), light_dirs=lights, view_dirs=views, k=12)
    truth = constraint_images(reference)
    # Registered scans in the first scan's frame: input i lit from azimuth 90 (1 + i) of
    # the truth, all turned by one quarter turn (the first scan's turn).
    inputs = [np.rot90(truth[(1 + i) % 4], 1) for i in range(4)]
    images, hypothesis, costs = orient_to_sample(inputs, constraint_images(sample), n_texels=1500)
    assert hypothesis == (3, 1, False)
    for got, want in zip(images, truth, strict=True):
        np.testing.assert_array_equal(got, want)
    ranked = sorted(costs.values())
    assert ranked[1] > 1.2 * ranked[0]  # measured 1.49


def test_a_scan_of_another_material_is_flagged(cloth, caplog):
    """The registration's confidence: correct alignments score 20 and more (measured
    20.7-187 on the four materials), a scan of another material a few (1.5-13.5)."""
    from imagemap.btf.materials import make_material
    from imagemap.btf.registration import MIN_CONFIDENCE
    from imagemap.btf.rendering import render_btf_matrix

    order, angles = [2, 0, 3, 1], [0.0, 3.0, -2.5, 1.5]
    shifts = [(0.0, 0.0), (-2.5, 4.0), (3.0, -1.5), (1.0, 3.5)]
    scans = _scans(cloth, order, angles, shifts)
    good = register_scans(scans)
    assert good.suspect == () and min(good.confidences) > 2 * MIN_CONFIDENCE  # measured 62
    wood = make_material("wood", size=SIZE, seed=11)  # another material, another noise seed
    lights = np.array([[22.0, a] for a in (0, 90, 180, 270)], np.float32)
    matrix = render_btf_matrix(wood, lights, np.array([[0.0, 0.0]], np.float32))
    wood_images = [
        matrix[3 * i : 3 * i + 3].reshape(3, SIZE, SIZE).transpose(1, 2, 0) for i in range(4)
    ]
    scans[3] = _scans(wood_images, order, angles, shifts)[3]
    names = ["a.png", "b.png", "c.png", "wood.png"]
    with caplog.at_level("WARNING", logger="imagemap"):
        bad = register_scans(scans, names=names)
    assert bad.suspect == (3,) and bad.confidences[3] < MIN_CONFIDENCE / 3  # measured 3.3
    assert "wood.png does not fit a.png" in caplog.text
    # Scans too small to judge (48 px: correct alignments from 5.6) are not judged.
    small = [s[32:80, 32:80] for s in _scans(cloth, [0, 1, 2, 3], [0.0] * 4, [(0.0, 0.0)] * 4)]
    reg = register_scans(small, max_rotation=0)
    assert reg.suspect == () and np.isnan(reg.confidences[1:]).all()
