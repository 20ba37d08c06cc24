"""The copy's seams solved coarse to fine (core/seams.place_seams, ``coarse_above``): on
2x2 blocks, then at full size in a band around the coarse seams."""

import numpy as np
import pytest
from scipy import ndimage
from test_seams import energy

from imagemap.core.seams import place_seams

LABELS = [(0, 5, 7), (1, 9, 2), (0, 12, 3), (1, 2, 11), (0, 3, 3), (1, 13, 6)]


def problem(height=101, width=97, seed=0, tiled=1 / 3):
    """Two smooth textures; a reference copied through label 0 inside a disc and
    label 1 around it (with noise); a start of those labels with a share of its 6x6
    tiles from six others, a masked-out strip and a hole, and the disc's centre a
    group."""
    rng = np.random.default_rng(seed)
    exemplars = [
        (4 * ndimage.gaussian_filter(rng.random((height + 20, width + 20, 3)), (2, 2, 0))).astype(
            np.float32
        )
        for _ in range(2)
    ]
    rows, columns = np.indices((height, width))
    disc = np.hypot(rows - height / 2, columns - width / 2) < 0.3 * min(height, width)
    # The start: the disc's labels, but a share (``tiled``) of the 6x6 tiles from another
    # label (all of them: a start the full solve leaves in a poorer local minimum).
    tile = (rows // 6) * (width // 6 + 1) + columns // 6
    other = rng.integers(0, len(LABELS), size=tile.max() + 1)
    other = np.where(rng.random(tile.max() + 1) < tiled, other, -1)[tile]
    chosen = np.array(LABELS)[np.where(other >= 0, other, np.where(disc, 0, 1))]
    source = np.stack([chosen[..., 0], rows + chosen[..., 1], columns + chosen[..., 2]], -1)
    copy0 = exemplars[0][rows + 5, columns + 7]
    copy1 = exemplars[1][rows + 9, columns + 2]
    reference = np.where(disc[..., None], copy0, copy1)
    reference = (reference + rng.normal(0, 0.05, reference.shape)).astype(np.float32)
    mask = np.ones((height, width), bool)
    mask[:3] = False
    mask[60:66, 20:30] = False
    groups = (np.hypot(rows - height / 2, columns - width / 2) < 4).astype(np.int64)
    return exemplars, source, reference, mask, groups


def seams_of(source, mask):
    """The pixels with a 4-neighbour in the mask of another label."""
    labels = source - np.stack([np.zeros(mask.shape, int), *np.indices(mask.shape)], -1)
    out = np.zeros(mask.shape, bool)
    for axis in (0, 1):
        differ = (np.diff(labels, axis=axis) != 0).any(-1)
        pair = np.diff(mask.astype(int), axis=axis) == 0
        pair &= mask[1:] if axis == 0 else mask[:, 1:]
        across = differ & pair
        if axis == 0:
            out[1:] |= across
            out[:-1] |= across
        else:
            out[:, 1:] |= across
            out[:, :-1] |= across
    return out


def test_below_the_switch_the_solve_is_the_full_one():
    exemplars, source, reference, mask, groups = problem(40, 36)
    full = place_seams(exemplars, source, reference, mask=mask, groups=groups)
    same = place_seams(exemplars, source, reference, mask=mask, groups=groups, coarse_above=40 * 36)
    np.testing.assert_array_equal(same, full)


@pytest.mark.parametrize("coarse_above", [101 * 97 // 4, 101 * 97 // 16])  # 1 and 2 levels
def test_coarse_to_fine_finds_the_full_solves_energy_and_seams(coarse_above):
    exemplars, source, reference, mask, groups = problem()
    start = energy(exemplars, source, reference, mask)
    full = place_seams(exemplars, source, reference, mask=mask, groups=groups)
    banded = place_seams(
        exemplars, source, reference, mask=mask, groups=groups, coarse_above=coarse_above
    )
    assert banded.dtype == np.int32 and banded.shape == source.shape
    np.testing.assert_array_equal(banded[~mask], source[~mask])  # fixed pixels kept
    # Only labels in use are used, and the group keeps its own.
    used = {tuple(v) for v in (source - np.stack([0 * mask, *np.indices(mask.shape)], -1))[mask]}
    labels = banded - np.stack([0 * mask, *np.indices(mask.shape)], -1)
    assert {tuple(v) for v in labels[mask]} <= used
    grouped = groups.astype(bool) & mask
    in_group = {
        tuple(v) for v in (source - np.stack([0 * mask, *np.indices(mask.shape)], -1))[grouped]
    }
    assert {tuple(v) for v in labels[grouped]} <= in_group
    e_full = energy(exemplars, full, reference, mask)
    e_banded = energy(exemplars, banded, reference, mask)
    assert e_full < 0.5 * start
    assert e_banded <= 1.05 * e_full
    # The seams lie where the full solve puts them, to within the band (4 px).
    near = ndimage.maximum_filter(seams_of(banded, mask), size=9)
    assert near[seams_of(full, mask)].mean() > 0.95


def test_from_a_fragmented_start_the_energy_stays_near_the_full_solves():
    exemplars, source, reference, mask, groups = problem(tiled=1.0)
    full = energy(exemplars, place_seams(exemplars, source, reference, mask=mask), reference, mask)
    for coarse_above in (101 * 97 // 4, 101 * 97 // 16):
        banded = place_seams(exemplars, source, reference, mask=mask, coarse_above=coarse_above)
        assert energy(exemplars, banded, reference, mask) <= 1.05 * full


def test_coarse_to_fine_keeps_to_the_exemplars_objects_and_ignores_unused_ones():
    exemplars, source, reference, mask, groups = problem()
    objects = [np.ones(e.shape[:2], bool) for e in exemplars]
    objects[1][:, :40] = False  # label 1's sources left of column 40: not to be taken
    kwargs = dict(mask=mask, groups=groups, coarse_above=101 * 97 // 16)
    banded = place_seams(exemplars, source, reference, exemplar_masks=objects, **kwargs)
    changed = (banded != source).any(-1) & mask
    e, y, x = banded[changed].T
    assert changed.any() and all(objects[k][y[e == k], x[e == k]].all() for k in (0, 1))
    # An example no pixel copies changes nothing (it is cut away).
    unused = np.zeros((300, 300, 3), np.float32)
    again = place_seams(
        [*exemplars, unused],
        source,
        reference,
        exemplar_masks=[*objects, np.ones((300, 300), bool)],
        **kwargs,
    )
    np.testing.assert_array_equal(again, banded)


@pytest.mark.parametrize("coarse_above", [None, 612])
def test_the_exemplars_cut_to_what_the_labels_read_give_the_same_labels(monkeypatch, coarse_above):
    """Every solve reads only the part of each exemplar its labels can reach (an unused
    exemplar dropped): the same labels as from the whole exemplars, extra channels too."""
    from imagemap.core import seams
    from imagemap.core.seams import with_channels

    exemplars, source, reference, mask, groups = problem(60, 56)
    rng = np.random.default_rng(1)
    # 30 px more below and right of what the labels read, and a third exemplar unused.
    exemplars = [np.pad(e, ((0, 30), (0, 30), (0, 0)), mode="reflect") for e in exemplars]
    exemplars.append(exemplars[0][::-1].copy())
    objects = [np.zeros(e.shape[:2], bool) for e in exemplars]
    for k, (rows, columns) in enumerate([(76, 70), (74, 68), (70, 70)]):
        objects[k][:rows, 3 * k : columns] = True
    planes = [[(0.5, rng.random(e.shape[:2]).astype(np.float32))] for e in exemplars]
    reference = with_channels(reference, [(0.5, np.full(mask.shape, 0.5))])
    kwargs = dict(
        mask=mask,
        groups=groups,
        exemplar_masks=objects,
        exemplar_channels=planes,
        coarse_above=coarse_above,
    )
    read = []
    real = seams._crops

    def spy(*args):
        corners, crops, crop_masks = real(*args)
        read.extend(crop.shape[:2] for crop in crops)
        return corners, crops, crop_masks

    monkeypatch.setattr(seams, "_crops", spy)
    cut = place_seams(exemplars, source, reference, **kwargs)
    assert read[:3] == [(84, 78), (82, 76), (0, 0)]  # of (110, 106) each
    whole = lambda exemplars, masks, source, mask: (  # noqa: E731
        np.zeros((len(exemplars), 2), np.int64),
        exemplars,
        masks,
    )
    monkeypatch.setattr(seams, "_crops", whole)
    np.testing.assert_array_equal(cut, place_seams(exemplars, source, reference, **kwargs))
