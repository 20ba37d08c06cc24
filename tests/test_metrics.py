"""Metrics of synthesized image-maps: known pairs, invariants, the faulty rule."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from scipy import ndimage
from skimage import color

from imagemap.align import paste_aligned
from imagemap.database import Example
from imagemap.io import InputError
from imagemap.metrics import (
    FaultyRule,
    ImageMetrics,
    blur_ratio,
    ciede2000,
    class_reference,
    image_metrics,
    luminance_ssim,
    part_accuracy,
)

RED, BLUE, GREEN = (0.85, 0.15, 0.1), (0.1, 0.2, 0.8), (0.2, 0.7, 0.25)


def three_parts(shape=(40, 50)):
    """Flat-coloured parts: 1 = top band (red), 2 = middle (blue), 3 = bottom (green)."""
    h, w = shape
    labels = np.zeros(shape, dtype=np.int32)
    labels[5:15, 5:45] = 1
    labels[15:22, 5:45] = 2
    labels[22:35, 5:45] = 3
    image = np.zeros(shape + (3,), dtype=np.float32)
    for part, colour in ((1, RED), (2, BLUE), (3, GREEN)):
        image[labels == part] = colour
    return image, labels


def test_identical_images_score_perfectly_even_with_patterned_parts():
    image, labels = three_parts()
    # Stripes inside part 1 (two colours of one part) and noise on part 3: the truth's
    # own part accuracy must still be 1, so a patterned part is judged by all its colours.
    image[(labels == 1) & (np.arange(50) % 4 < 2)[None, :]] = (0.95, 0.8, 0.2)
    rng = np.random.default_rng(0)
    image[labels == 3] += rng.normal(0, 0.03, size=(int((labels == 3).sum()), 3))
    image = np.clip(image, 0, 1)
    m = image_metrics(image, image, labels > 0, labels)
    assert m.ciede2000 == 0.0
    assert m.ssim == pytest.approx(1.0, abs=1e-9)
    assert m.part_accuracy == 1.0


def test_colour_swap_between_parts_by_hand():
    truth, labels = three_parts()
    swapped = truth.copy()
    swapped[labels == 1] = BLUE
    swapped[labels == 2] = RED
    mask = labels > 0
    n1, n2, n3 = ((labels == p).sum() for p in (1, 2, 3))
    # Parts 1 and 2 are now exactly the other's colour: only part 3 is right.
    assert part_accuracy(swapped, truth, labels) == pytest.approx(n3 / (n1 + n2 + n3))
    lab_red, lab_blue = (color.rgb2lab(np.array([c], np.float32)) for c in (RED, BLUE))
    delta = float(color.deltaE_ciede2000(lab_red, lab_blue)[0])
    assert ciede2000(swapped, truth, mask) == pytest.approx((n1 + n2) * delta / mask.sum(), 1e-4)
    assert luminance_ssim(swapped, truth, mask) < 0.95


def test_part_accuracy_counts_only_the_pixels_that_moved_to_the_wrong_side():
    truth, labels = three_parts()
    synthesized = truth.copy()
    # Half of part 2 painted green (part 3's colour); a slightly darker red on part 1
    # is still nearer to red than to anything else.
    rows = np.nonzero((labels == 2).any(axis=1))[0]
    synthesized[rows[:3][:, None], np.arange(5, 45)[None, :]] = GREEN
    synthesized[labels == 1] *= 0.9
    wrong = 3 * 40
    assert part_accuracy(synthesized, truth, labels) == pytest.approx(
        1 - wrong / (labels > 0).sum()
    )


def test_background_does_not_count():
    truth, labels = three_parts()
    noisy = truth.copy()
    noisy[labels == 0] = np.random.default_rng(1).random(((labels == 0).sum(), 3))
    assert image_metrics(noisy, truth, labels > 0, labels) == image_metrics(
        truth, truth, labels > 0, labels
    )


def test_single_part_has_no_part_accuracy_and_bad_input_is_named():
    truth, labels = three_parts()
    assert math.isnan(part_accuracy(truth, truth, (labels > 0).astype(int)))
    assert math.isnan(image_metrics(truth, truth, labels > 0).part_accuracy)
    with pytest.raises(InputError, match="mask is empty"):
        ciede2000(truth, truth, np.zeros(labels.shape, bool))
    with pytest.raises(InputError, match="must both be"):
        ciede2000(truth[:, :-1], truth, labels > 0)


def test_ssim_sees_structure_not_just_colour():
    truth, labels = three_parts()
    mask = labels > 0
    stripes = truth.copy()
    stripes[(labels == 3) & (np.arange(50) % 6 < 3)[None, :]] *= 0.4
    flat_darker = truth * 0.97
    assert luminance_ssim(stripes, truth, mask) < luminance_ssim(flat_darker, truth, mask) - 0.1


def test_paste_aligned_moves_the_centroid():
    image, labels = three_parts()
    mask = labels > 0
    target = np.roll(mask, (3, -2), axis=(0, 1))
    pasted = paste_aligned(image, mask, target)
    np.testing.assert_array_equal(pasted, np.roll(image, (3, -2), axis=(0, 1)))


def test_faulty_rule_limits():
    rule = FaultyRule(ssim=0.5, part_transfer=0.8)
    assert not rule.is_faulty(ImageMetrics(90.0, 0.5, 0.0, 0.8))  # palette metrics unused
    assert rule.is_faulty(ImageMetrics(1.0, 0.49, 1.0, 0.9))
    assert rule.is_faulty(ImageMetrics(1.0, 0.9, 1.0, 0.79))
    assert not rule.is_faulty(ImageMetrics(1.0, 0.9, 1.0))  # NaN transfer fails nothing
    assert FaultyRule(ciede2000=10.0).is_faulty(ImageMetrics(10.01, 1.0, 1.0))
    assert (
        rule.describe() == "SSIM < 0.500 or part transfer < 0.800 or a small feature is not drawn"
    )
    assert FaultyRule(features=False).describe() == "never"
    # A missing small feature makes an otherwise fine map faulty.
    fine = ImageMetrics(1.0, 0.9, 1.0, 0.9, features_drawn=2, features_measured=2)
    assert not rule.is_faulty(fine)
    assert rule.is_faulty(replace(fine, features_drawn=1))
    assert not FaultyRule(ssim=0.5, features=False).is_faulty(replace(fine, features_drawn=1))


def test_class_reference_from_pastes():
    image, labels = three_parts()
    depth = np.where(labels > 0, 0.5, 0).astype(np.float32)
    shifted = Example.from_arrays(
        "b",
        np.roll(depth, 2, axis=1),
        np.roll(image, 2, axis=1),
        np.roll(labels, 2, axis=1),
    )
    same = Example.from_arrays("a", depth, image, labels)
    # The same map at another place: every paste is perfect, so the bar is perfection.
    rule, stats = class_reference([same, shifted])
    assert stats["pairs"] == 2
    assert rule.part_transfer == 1.0 and stats["ssim_quartiles"][1] == pytest.approx(1.0)
    # Labels known: neither the palette nor SSIM against the pastes is judged (#10, b).
    assert math.isnan(rule.ciede2000) and math.isnan(rule.ssim)
    assert stats["ciede2000_quartiles"][1] == pytest.approx(0.0, abs=1e-9)
    # Another palette on the same parts: colour is far off, parts are all right.
    recoloured = Example.from_arrays("c", depth, image[..., ::-1].copy(), labels)
    rule, stats = class_reference([same, recoloured])
    assert stats["ciede2000_quartiles"][1] > 20 and rule.part_transfer == 1.0
    # Without labels the colour is judged.
    unlabelled = [Example.from_arrays(e.name, e.depth, e.image) for e in (same, recoloured)]
    rule, _ = class_reference(unlabelled)
    assert rule.ciede2000 > 20 and math.isnan(rule.part_transfer)
    with pytest.raises(InputError):
        class_reference([same])


def test_blur_ratio_leaves_out_the_step_between_two_examples():
    """Issue #10's decision (c): a palette step between two examples, smoothed by the
    blend, is not lost detail; inside each example the ratio still sees blur."""
    rng = np.random.default_rng(1)
    texture = 0.05 * rng.standard_normal((40, 40))
    copy = np.repeat((0.3 + texture)[..., None], 3, axis=2).astype(np.float32)
    copy[:, 20:] += 0.5  # the second example's palette
    source = np.zeros((40, 40, 3), np.int32)
    source[:, 20:, 0] = 1
    step = np.clip((np.arange(40) - 14) / 12, 0, 1)[None, :, None]  # a 12 px ramp
    blended = (copy - 0.5 * (np.arange(40) >= 20)[None, :, None] + 0.5 * step).astype(np.float32)
    mask = np.ones((40, 40), bool)
    assert blur_ratio(blended, copy, mask) < 0.9  # the step's energy counted as detail
    assert blur_ratio(blended, copy, mask, source) == pytest.approx(1.0, abs=0.05)
    blurred = ndimage.uniform_filter(copy, (3, 3, 1))
    assert blur_ratio(blurred, copy, mask, source) < 0.5


def test_the_faulty_rule_of_a_labelled_class_has_no_ssim_limit():
    """Issue #10's decision (b): faulty is a missing feature or part transfer below the
    pastes' median; the SSIM half is dropped."""
    from imagemap.database import Example

    examples = []
    for i in range(3):
        depth = np.zeros((30, 40), np.float32)
        depth[5 + i : 25, 8 : 30 + i] = 0.5
        labels = (depth > 0).astype(np.int32)
        labels[5 + i : 12, 8 : 30 + i] = 2
        image = (
            np.where(labels[..., None] == 2, [0.8, 0.2, 0.2], [0.2, 0.2, 0.8])
            * (depth > 0)[..., None]
        )
        examples.append(Example.from_arrays(f"c_{i}", depth, image, labels=labels))
    rule, _ = class_reference(examples)
    assert np.isnan(rule.ssim) and not np.isnan(rule.part_transfer)
    assert "SSIM" not in rule.describe()
