"""Coherence measures (issue #32): fragments, seams, palettes per part, continuity, mid-tones."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import ndimage

from imagemap.align import aligned_source
from imagemap.io import InputError
from imagemap.metrics import (
    FRAGMENT_COVERAGE,
    FragmentStats,
    fragment_labels,
    fragments,
    midtone_share,
    palettes_per_part,
    seam_length,
    structure_continuity,
)

SHAPE = (60, 80)


def identity_source(shape=SHAPE, example=0, dy=0, dx=0) -> np.ndarray:
    """A source map that copies one example translated by (dy, dx)."""
    rows, columns = np.indices(shape)
    return np.stack([np.full(shape, example), rows + dy, columns + dx], -1).astype(np.int32)


def ellipse(shape=SHAPE) -> np.ndarray:
    rows, columns = np.indices(shape)
    h, w = shape
    return ((rows - h / 2) / (0.4 * h)) ** 2 + ((columns - w / 2) / (0.4 * w)) ** 2 < 1


def striped(shape=(128, 128), period=24.0, softness=0.15, colour=True) -> np.ndarray:
    """Vertical stripes with slightly soft edges (a truth has anti-aliased edges)."""
    x = np.arange(shape[1])
    wave = np.clip(0.5 + np.sin(2 * np.pi * x / period) / (2 * softness), 0, 1)
    grey = np.tile(0.2 + 0.6 * wave, (shape[0], 1))
    if not colour:
        return grey
    return np.stack([grey, 0.8 * grey, 0.5 * grey], -1)


# -- fragments ---------------------------------------------------------------------


def test_one_translated_copy_is_one_fragment():
    stats = fragments(identity_source(dy=7, dx=-3), ellipse())
    assert (stats.count_90, stats.mean_share, stats.count) == (1, 1.0, 1)


def test_two_halves_are_two_fragments_of_half_each():
    source = identity_source()
    source[:, 40:, 2] += 12  # the right half copied from 12 px further right
    stats = fragments(source, np.ones(SHAPE, bool))
    assert (stats.count_90, stats.count) == (2, 2)
    assert stats.mean_share == pytest.approx(0.5)
    # Another example instead of another offset: the same two pieces.
    other = identity_source()
    other[:, 40:, 0] = 1
    assert fragments(other, np.ones(SHAPE, bool)) == stats


def test_checkerboard_of_tiny_patches_is_many_fragments():
    source = identity_source()
    rows, columns = np.indices(SHAPE)
    tile = (rows // 4 + columns // 4) % 2 == 1
    source[tile, 1] += 9  # every other 4x4 tile jumps by 9 px
    stats = fragments(source, np.ones(SHAPE, bool))
    assert stats.count == (SHAPE[0] // 4) * (SHAPE[1] // 4)
    assert stats.count_90 >= FRAGMENT_COVERAGE * stats.count - 1
    assert stats.mean_share == pytest.approx(1 / stats.count)


def test_a_slow_drift_stays_one_fragment_and_a_jump_does_not():
    source = identity_source()
    _, columns = np.indices(SHAPE)
    source[..., 2] = 2 * columns  # stretched copy: offset grows 1 px per pixel
    assert fragments(source, np.ones(SHAPE, bool)).count == 1
    # A copy through a scale or a turn steps by its own usual step: one piece...
    source[..., 2] = 3 * columns
    assert fragments(source, np.ones(SHAPE, bool)).count == 1
    # ...and a jump to another place of the example within it starts another.
    source[:, SHAPE[1] // 2 :, 2] += 10
    assert fragments(source, np.ones(SHAPE, bool)).count == 2
    # Mirrored (the columns read backwards): one piece too.
    source[..., 2] = SHAPE[1] - 1 - columns
    assert fragments(source, np.ones(SHAPE, bool)).count == 1


def test_copy_nearest_source_is_one_fragment_whatever_its_holes():
    query = ellipse()
    for erosion in (1, 4):  # holes of 6 % and 23 % of the object
        smaller = ndimage.binary_erosion(ellipse(), iterations=erosion)
        source = aligned_source(smaller, query)
        assert (query & (source[..., 0] < 0)).any()
        assert fragments(source, query) == FragmentStats(count_90=1, mean_share=1.0, count=1)
        assert fragment_labels(source, query)[query & (source[..., 0] < 0)].max() == 0
    nothing = np.full(SHAPE + (3,), -1)
    assert fragments(nothing, query).count == 0


def test_fragment_labels_are_deterministic_and_numbered_in_raster_order():
    source = identity_source()
    source[30:, :, 0] = 1
    labels = fragment_labels(source, np.ones(SHAPE, bool))
    assert labels[0, 0] == 1 and labels[-1, -1] == 2
    assert set(np.unique(labels)) == {1, 2}


# -- seams -------------------------------------------------------------------------


def test_one_straight_seam_is_its_length():
    source = identity_source()
    source[:, 50:, 0] = 1
    mask = np.ones(SHAPE, bool)
    assert seam_length(source, mask, per_outline=False) == SHAPE[0]
    assert seam_length(source, mask) == pytest.approx(SHAPE[0] / (2 * sum(SHAPE)))
    assert seam_length(identity_source(dx=4), mask) == 0.0


def test_seams_follow_the_fragments_and_holes_are_not_seams_between_holes():
    source = identity_source()
    source[20:40, 30:50, 0] = -1  # a 20x20 hole: its border is a seam, its inside is not
    mask = np.ones(SHAPE, bool)
    assert seam_length(source, mask, per_outline=False) == 4 * 20


# -- palettes per part -------------------------------------------------------------


def test_two_examples_inside_one_part_are_two_palettes():
    labels = np.zeros(SHAPE, int)
    labels[5:55, 5:40] = 1
    labels[5:55, 40:75] = 2
    source = identity_source()
    source[30:, 5:40, 0] = 1  # part 1 painted half from example 1
    source[5, 40:75, 0] = 1  # one row of part 2 from example 1 (2 %): under the minimum
    count = palettes_per_part(source, labels)
    assert count.per_part == {1: 2, 2: 1}
    assert count.one_palette_share == 0.5 and not count.all_one
    single = palettes_per_part(identity_source(), labels)
    assert single.per_part == {1: 1, 2: 1} and single.all_one
    # Lower the minimum below the sliver's share: part 2 has two palettes too.
    assert palettes_per_part(source, labels, min_share=0.01).per_part == {1: 2, 2: 2}


# -- continuity and mid-tones ------------------------------------------------------


def patchwork(image: np.ndarray, block: int, jitter: int, seed: int = 0) -> np.ndarray:
    """The image copied in ``block`` px tiles, each from up to ``jitter`` px away."""
    rng = np.random.default_rng(seed)
    h, w = image.shape[:2]
    rows, columns = np.indices((h, w))
    tiles = (rows // block, columns // block)
    shape = (h // block + 1, w // block + 1)
    dy, dx = (rng.integers(-jitter, jitter + 1, shape)[tiles] for _ in range(2))
    return image[np.clip(rows + dy, 0, h - 1), np.clip(columns + dx, 0, w - 1)]


def test_blur_keeps_continuity_and_raises_midtones():
    truth = striped()
    mask = np.ones(truth.shape[:2], bool)
    blurred = ndimage.gaussian_filter(truth, (3, 3, 0))
    assert structure_continuity(blurred, truth, mask) == pytest.approx(1.0, abs=0.03)
    assert structure_continuity(truth, truth, mask) == 1.0
    assert midtone_share(truth, truth, mask) == 1.0
    assert midtone_share(blurred, truth, mask) > 1.5


def test_a_crisp_shifted_copy_is_as_crisp_and_orderly_as_the_truth():
    truth = striped()
    mask = np.ones(truth.shape[:2], bool)
    for shift in (3, 9):  # a quarter and three quarters of a stripe's width
        shifted = np.roll(truth, shift, axis=1)
        assert midtone_share(shifted, truth, mask) == pytest.approx(1.0, abs=0.1)
        assert structure_continuity(shifted, truth, mask) == pytest.approx(1.0, abs=0.02)


def test_a_map_in_another_pattern_is_judged_in_its_own_edges():
    # A checked truth, a crisply striped map (another garment): as crisp as the truth.
    truth = striped() * striped().transpose(1, 0, 2)
    mask = np.ones(truth.shape[:2], bool)
    other = striped(period=30.0)
    crisp = midtone_share(other, truth, mask)
    assert crisp < 1.3
    assert midtone_share(ndimage.gaussian_filter(other, (3, 3, 0)), truth, mask) > 1.5 * crisp


def test_two_copies_averaged_are_ghosted():
    truth = striped()
    mask = np.ones(truth.shape[:2], bool)
    ghosted = 0.5 * (truth + np.roll(truth, 4, axis=1))
    assert midtone_share(ghosted, truth, mask) > 1.5


def test_fragmented_stripes_lose_continuity_and_a_flat_map_has_neither_measure():
    truth = striped()
    mask = np.ones(truth.shape[:2], bool)
    assert structure_continuity(patchwork(truth, 8, 6), truth, mask) < 0.8
    flat = np.full_like(truth, 0.5)
    assert math.isnan(structure_continuity(flat, truth, mask))  # no structure at all
    assert math.isnan(midtone_share(flat, truth, mask))  # no edge to be crisp or soft


def test_measures_stay_inside_the_mask():
    # The same stripes inside an ellipse: the outline must not count as structure.
    truth = striped(SHAPE)
    mask = ellipse()
    outside = truth.copy()
    outside[~mask] = 1.0 - outside[~mask]  # anything outside the object
    assert structure_continuity(outside, truth, mask) == pytest.approx(1.0)
    assert midtone_share(outside, truth, mask) == pytest.approx(1.0)


def test_grey_images_with_channel_axis_none():
    truth = striped(colour=False)
    mask = np.ones(truth.shape, bool)
    blurred = ndimage.gaussian_filter(truth, 3)
    assert midtone_share(blurred, truth, mask, channel_axis=None) > 1.5


@pytest.mark.parametrize(
    "call",
    [
        lambda: fragments(np.zeros((4, 4, 2), int), np.ones((4, 4), bool)),
        lambda: fragments(np.zeros((4, 4, 3), float), np.ones((4, 4), bool)),
        lambda: fragments(np.zeros((4, 4, 3), int), np.zeros((4, 4), bool)),
        lambda: seam_length(np.zeros((4, 4, 3), int), np.ones((3, 4), bool)),
        lambda: palettes_per_part(np.zeros((4, 4, 3), int), np.ones((4, 5), int)),
        lambda: structure_continuity(np.zeros((4, 4, 3)), np.zeros((4, 4, 3)), np.zeros((4, 4))),
        lambda: midtone_share(np.zeros((4, 4, 2)), np.zeros((4, 4, 2)), np.ones((4, 4), bool)),
    ],
)
def test_bad_input_is_named(call):
    with pytest.raises(InputError):
        call()
