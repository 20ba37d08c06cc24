"""The copy's seams: labels rearranged by alpha-expansion graph cuts (core/seams.place_seams)."""

import numpy as np
import pytest

from imagemap.core.seams import place_seams

FLOOR = 1e-3  # core.seams._SEAM_FLOOR


def labels_of(source):
    rows, columns = np.indices(source.shape[:2])
    return np.stack([source[..., 0], source[..., 1] - rows, source[..., 2] - columns], -1)


def colours(exemplars, source):
    """Each pixel's copied colour and whether its source lies inside its exemplar."""
    out = np.zeros(source.shape[:2] + (exemplars[0].shape[2],))
    valid = np.zeros(source.shape[:2], bool)
    for k, exemplar in enumerate(exemplars):
        e, y, x = source[..., 0], source[..., 1], source[..., 2]
        inside = (e == k) & (y >= 0) & (x >= 0) & (y < exemplar.shape[0]) & (x < exemplar.shape[1])
        out[inside] = exemplar[y[inside], x[inside]]
        valid |= inside
    return out, valid


def energy(exemplars, source, reference, mask, smoothness=1.0):
    """The energy place_seams minimises, written out independently of its kernel."""
    copied, valid = colours(exemplars, source)
    assert valid[mask].all()
    total = float(((copied - reference) ** 2).sum(-1)[mask].sum())
    labels = labels_of(source)
    rows, columns = np.indices(mask.shape)
    for axis in (0, 1):
        p = (slice(None, -1), slice(None)) if axis == 0 else (slice(None), slice(None, -1))
        q = (slice(1, None), slice(None)) if axis == 0 else (slice(None), slice(1, None))
        pairs = mask[p] & mask[q] & (labels[p] != labels[q]).any(-1)
        # the p-label read at q and the q-label read at p
        lp_at_q = np.stack(
            [labels[p][..., 0], labels[p][..., 1] + rows[q], labels[p][..., 2] + columns[q]], -1
        )
        lq_at_p = np.stack(
            [labels[q][..., 0], labels[q][..., 1] + rows[p], labels[q][..., 2] + columns[p]], -1
        )
        a, av = copied[p], valid[p]
        b, bv = colours(exemplars, lq_at_p)
        c, cv = colours(exemplars, lp_at_q)
        d, dv = copied[q], valid[q]
        gap_p = np.where(av & bv, np.linalg.norm(a - b, axis=-1), 1.0)
        gap_q = np.where(cv & dv, np.linalg.norm(c - d, axis=-1), 1.0)
        total += smoothness * float((FLOOR + gap_p + gap_q)[pairs].sum())
    return total


def stripes(height=64, width=64, period=2.0):
    return np.repeat(np.sin(np.arange(height) / period)[:, None], width, axis=1)[..., None]


def shifted(shape, shift, base=8):
    rows, columns = np.indices(shape)
    return np.stack([np.zeros_like(rows), rows + base + shift, columns + base], -1)


def test_the_energy_goes_down_and_only_labels_in_use_are_used():
    rng = np.random.default_rng(3)
    exemplars = [rng.random((40, 40, 3)).astype(np.float32) for _ in range(2)]
    rows, columns = np.indices((24, 24))
    # Blocks of 4x4, each from a random exemplar at one of four offsets.
    block = (rows // 4) * 6 + columns // 4
    choice = rng.integers(0, 8, size=block.max() + 1)[block]
    source = np.stack([choice // 4, rows + 4 + choice % 4, columns + 4 + (choice % 4) * 2], -1)
    reference = colours(exemplars, source)[0] + 0.1 * rng.standard_normal((24, 24, 3))
    mask = np.ones((24, 24), bool)
    placed = place_seams(exemplars, source, reference)
    before = energy(exemplars, source, reference, mask)
    after = energy(exemplars, placed, reference, mask)
    assert after < 0.9 * before, (before, after)
    used = {tuple(v) for v in labels_of(source).reshape(-1, 3)}
    assert {tuple(v) for v in labels_of(placed).reshape(-1, 3)} <= used
    again = place_seams(exemplars, source, reference)
    np.testing.assert_array_equal(placed, again)


def test_a_whole_fragment_gives_way_where_pixel_by_pixel_moves_cannot():
    """A 10x10 piece of stripes copied 3 rows off inside one large copy, where the voted
    map cannot tell the two apart (their mean): changing one pixel inside it only adds
    seams, so pixel-by-pixel moves (iterated conditional modes, used before) left 60 of
    its 100 pixels; one expansion move removes it."""
    image = stripes()
    source = shifted((32, 32), 0)
    source[11:21, 11:21, 1] += 3
    voted = image[source[..., 1], source[..., 2]].astype(np.float64)
    both = (image[8:40, 8:40] + image[11:43, 8:40]) / 2
    voted[11:21, 11:21] = both[11:21, 11:21]
    placed = place_seams([image], source, voted)
    offsets = labels_of(placed)[..., 1]
    assert np.unique(offsets).tolist() == [8]
    mask = np.ones((32, 32), bool)
    assert energy([image], placed, voted, mask) < energy([image], source, voted, mask)


def test_a_feature_the_voted_map_shows_is_kept():
    """A dark spot copied from its own place in the exemplar, on a plain ground copied
    from elsewhere: the voted map shows the spot, so its copy stays whole."""
    exemplar = np.full((64, 64, 3), 0.7, np.float32)
    exemplar[40:46, 40:46] = 0.05  # the spot
    source = shifted((32, 32), 0, base=2)
    source[13:19, 13:19, 1] += 25  # (13..18) + 2 + 25 = 40..45: the spot
    source[13:19, 13:19, 2] += 25
    voted = colours([exemplar], source)[0]
    placed = place_seams([exemplar], source, voted)
    np.testing.assert_array_equal(placed[13:19, 13:19], source[13:19, 13:19])
    assert colours([exemplar], placed)[0][13:19, 13:19].max() < 0.1


def test_pixels_outside_the_mask_or_without_a_source_are_left_alone():
    image = stripes()
    source = shifted((32, 32), 0)
    source[:, 16:, 1] += 3
    source[0:4, 0:4] = -1  # no source
    voted = (image[8:40, 8:40] + image[11:43, 8:40]) / 2
    mask = np.ones((32, 32), bool)
    mask[:, 28:] = False
    placed = place_seams([image], source, voted, mask=mask)
    np.testing.assert_array_equal(placed[:, 28:], source[:, 28:])
    np.testing.assert_array_equal(placed[0:4, 0:4], source[0:4, 0:4])
    # inside, the two halves became one copy
    assert len(np.unique(labels_of(placed)[4:, :28, 1])) == 1


def test_a_feature_copied_in_pieces_becomes_one_of_its_own_copies():
    """A dark spot copied half from one example's spot and half from another's (paler
    ground), inside a ground copied from the first: as a group, the spot may only take
    its own two labels, so it becomes the first example's spot whole (the second's
    outline shows its paler ground) and never the ground, even where the voted map
    missed the spot."""
    first = np.full((64, 64, 3), 0.7, np.float32)
    first[40:46, 40:46] = 0.05
    second = np.full((64, 64, 3), 0.6, np.float32)
    second[20:26, 20:26] = 0.05
    source = shifted((32, 32), 0, base=2)
    source[13:19, 13:19, 1:] += 25  # the first example's spot
    source[13:19, 16:19, 0] = 1  # its right half from the second's spot
    source[13:19, 16:19, 1:] -= 20
    groups = np.zeros((32, 32), int)
    groups[13:19, 13:19] = 1
    spot_labels = {tuple(v) for v in labels_of(source)[13:19, 13:19].reshape(-1, 3)}
    assert len(spot_labels) == 2
    shown = colours([first, second], source)[0]
    placed = place_seams([first, second], source, shown, groups=groups)
    spot = labels_of(placed)[13:19, 13:19].reshape(-1, 3)
    assert {tuple(v) for v in spot} == {(0, 27, 27)}  # the first example's spot, whole
    assert colours([first, second], placed)[0][13:19, 13:19].max() < 0.1
    missed = np.full((32, 32, 3), 0.7)  # a voted map without the spot
    placed = place_seams([first, second], source, missed, groups=groups)
    assert {tuple(v) for v in labels_of(placed)[13:19, 13:19].reshape(-1, 3)} <= spot_labels
    assert colours([first, second], placed)[0][13:19, 13:19].max() < 0.1


def test_seams_weigh_nothing_where_their_weights_are_zero():
    """A piece of stripes copied 3 rows off, which the voted map shows: strong seams make
    it give way to the large copy around it; with the seams' weights 0 around it (where
    the query's relief says the matches, not the registered copy, know best) it stays,
    and weights of 1 everywhere are no weights at all."""
    image = stripes()
    source = shifted((32, 32), 0)
    source[11:21, 11:21, 1] += 3
    voted = image[source[..., 1], source[..., 2]].astype(np.float64)
    merged = place_seams([image], source, voted, smoothness=5.0)
    assert np.unique(labels_of(merged)[..., 1]).tolist() == [8]
    weights = np.ones((32, 32), np.float32)
    weights[9:23, 9:23] = 0.0
    kept = place_seams([image], source, voted, smoothness=5.0, weights=weights)
    np.testing.assert_array_equal(kept, source)
    ones = place_seams([image], source, voted, smoothness=5.0, weights=np.ones((32, 32)))
    np.testing.assert_array_equal(ones, merged)


def many_labels():
    """Exemplars, a source map of 40 labels of many areas and a reference near it."""
    rng = np.random.default_rng(5)
    exemplars = [rng.random((60, 60, 3)).astype(np.float32) for _ in range(2)]
    rows, columns = np.indices((48, 48))
    # Blocks of 12 px a side (top half), 3 px and 1 px, each from a random exemplar at
    # one of 20 offsets: 40 labels of many areas.
    size = np.where(rows < 24, 12, np.where(columns < 24, 3, 1))
    block = (rows // size) * 100 + columns // size + 10_000 * (size == 3) + 20_000 * (size == 1)
    choice = rng.integers(0, 40, size=block.max() + 1)[block]
    source = np.stack([choice % 2, rows + 4 + (choice // 2) % 5, columns + 4 + choice // 10], -1)
    reference = colours(exemplars, source)[0] + 0.1 * rng.standard_normal((48, 48, 3))
    return exemplars, source, reference


def test_the_numba_cut_gives_pymaxflows_labels_over_moves_of_many_sizes(monkeypatch):
    """The moves' minimum cut (core/flow.grid_cut, numba) gives the labels that PyMaxflow's
    cut gave (the one before it), over moves of many sizes."""
    pytest.importorskip("maxflow")  # the reference (the test extra installs it)
    from test_flow import pymaxflow_cut  # after the skip: test_flow needs maxflow

    from imagemap.core import flow

    exemplars, source, reference = many_labels()
    # smoothness 0.3: most copies stay, so that every label has a move
    numba_cut = place_seams(exemplars, source, reference, smoothness=0.3)
    sizes = []

    def recorded_cut(node, cost0, cost1, first, second, capacity):
        sizes.append(len(cost0))
        return pymaxflow_cut(node, cost0, cost1, first, second, capacity)

    monkeypatch.setattr(flow, "grid_cut", recorded_cut)
    reference_cut = place_seams(exemplars, source, reference, smoothness=0.3)
    assert len(sizes) >= 20 and max(sizes) > 10 * min(sizes), sizes  # many moves, unlike
    np.testing.assert_array_equal(numba_cut, reference_cut)
    assert (numba_cut != source).any()  # the moves changed labels


def test_the_data_costs_kept_between_moves_are_those_of_the_labels_left(monkeypatch):
    """The moves keep each pixel's data cost of its own label (0 until a move's terms
    gather it, and again where a cut changes the label): after the solve, every one known
    is the squared distance of the pixel's copied colour to the reference, bit for bit
    (float32 differences, squared in float32, summed in float64 channel by channel, as
    the kernel does)."""
    from imagemap.core import seams

    exemplars, source, reference = many_labels()
    made = []

    class Recorded(seams._Moves):
        def __init__(self, *args):
            super().__init__(*args)
            made.append(self)

    monkeypatch.setattr(seams, "_Moves", Recorded)
    placed = place_seams(exemplars, source, reference, smoothness=0.3)
    (moves,) = made
    changed = (placed != source).any(axis=-1)
    assert changed.mean() > 0.1  # many cuts applied
    known = moves.data_now != 0
    assert known.mean() > 0.5 and (known & changed).any()  # kept across changes too
    copied, valid = colours([e.astype(np.float32) for e in exemplars], placed)
    assert valid.all()
    gap = copied.astype(np.float32) - moves.reference
    expected = np.zeros(gap.shape[:2])
    for channel in range(gap.shape[2]):
        expected += (gap[..., channel] * gap[..., channel]).astype(np.float64)
    np.testing.assert_array_equal(moves.data_now[known], expected[known])


def tiles():
    """Exemplars, a source map of 64 tiles of 12 px a side, each its own label, and a
    reference showing each 2x2 group of tiles copied whole by one of its tiles' labels:
    with a short reach, the crops of many moves in turn are far apart."""
    rng = np.random.default_rng(2)
    exemplars = [rng.random((120, 120, 3)).astype(np.float32) for _ in range(2)]
    rows, columns = np.indices((96, 96))
    tile = (rows // 12) * 8 + columns // 12
    offsets_of = rng.integers(0, 24, size=(64, 2))
    offsets = offsets_of[tile]
    source = np.stack([tile % 2, rows + offsets[..., 0], columns + offsets[..., 1]], -1)
    group = (rows // 24) * 16 + (columns // 24) * 2
    target = np.stack(
        [group % 2, rows + offsets_of[group][..., 0], columns + offsets_of[group][..., 1]], -1
    )
    reference = colours(exemplars, target)[0] + 0.05 * rng.standard_normal((96, 96, 3))
    return exemplars, source, reference


def test_moves_run_in_pairs_find_what_the_moves_in_turn_find(monkeypatch):
    """Independent moves (crops more than a pixel apart) run two at a time on two threads,
    and a large move alone is cut on both (core/flow.grid_cut_halved): the labels are
    those of the moves one at a time on one thread, and pairs and halved cuts did run."""
    from imagemap.core import flow, kernels, seams

    exemplars, source, reference = tiles()
    pairs = []
    side_thread = seams._side_thread

    def counted():
        pairs.append(1)
        return side_thread()

    monkeypatch.setattr(seams, "_side_thread", counted)
    monkeypatch.setattr(kernels, "n_threads", lambda: 2)
    # moves of any size in pairs, and the larger ones alone cut on two threads
    monkeypatch.setattr(seams, "_PAIRED_PIXELS", 0)
    monkeypatch.setattr(seams, "_HALVED_NODES", 300)
    halved = []
    cut_halved = flow.grid_cut_halved

    def counted_halved(*args):
        halved.append(len(args[1]))
        return cut_halved(*args)

    monkeypatch.setattr(flow, "grid_cut_halved", counted_halved)
    paired = place_seams(exemplars, source, reference, smoothness=0.3, spread=0.5)
    assert len(pairs) >= 5 and len(halved) >= 5
    monkeypatch.setattr(kernels, "n_threads", lambda: 1)
    in_turn = place_seams(exemplars, source, reference, smoothness=0.3, spread=0.5)
    np.testing.assert_array_equal(paired, in_turn)
    assert (paired != source).any(axis=-1).mean() > 0.2  # the moves changed many labels


def test_a_partner_not_taken_is_cut_as_planned_and_planned_once(monkeypatch):
    """A move planned as the next one's partner and found too small to pair is cut next,
    in turn, from that plan (the move before it changes nothing the plan read): the labels
    are those of one thread, and every move is planned once."""
    from imagemap.core import kernels, seams

    exemplars, source, reference = tiles()
    plans, cuts = [], []
    planned, cut = seams._Moves._planned, seams._Moves._cut

    def counted_plan(self, *args):
        made = planned(self, *args)
        if made is not None:
            plans.append(made[0])
        return made

    def counted_cut(self, move, *args):
        cuts.append(move[0])
        return cut(self, move, *args)

    monkeypatch.setattr(seams._Moves, "_planned", counted_plan)
    monkeypatch.setattr(seams._Moves, "_cut", counted_cut)
    monkeypatch.setattr(kernels, "n_threads", lambda: 2)
    monkeypatch.setattr(seams, "_PAIRED_PIXELS", 10**9)  # every partner too small
    alone = place_seams(exemplars, source, reference, smoothness=0.3, spread=0.5)
    assert len(cuts) >= 20 and plans == cuts  # each planned once, in the order cut
    monkeypatch.setattr(kernels, "n_threads", lambda: 1)
    in_turn = place_seams(exemplars, source, reference, smoothness=0.3, spread=0.5)
    np.testing.assert_array_equal(alone, in_turn)
    assert (alone != source).any(axis=-1).mean() > 0.2


def test_two_moves_pair_only_with_a_pixel_between_their_crops():
    """seams._apart: a move writes labels in its crop and reads one pixel around it, so
    two moves may run at once only with at least one pixel between their crops (known
    answers: touching crops, one pixel between, overlapping, apart along one axis)."""
    from imagemap.core.seams import _apart

    def crop(r0, r1, c0, c1):
        return slice(r0, r1), slice(c0, c1), 1

    base = crop(0, 10, 0, 10)  # rows and columns 0..9
    assert not _apart(base, crop(10, 20, 0, 10))  # rows 9 and 10 touch
    assert not _apart(base, crop(0, 10, 10, 20))  # columns 9 and 10 touch
    assert not _apart(base, crop(10, 20, 10, 20))  # corners 9,9 and 10,10 touch diagonally
    assert not _apart(base, crop(5, 15, 5, 15))  # overlap
    assert _apart(base, crop(11, 20, 0, 10))  # row 10 between: neither writes what the other reads
    assert _apart(base, crop(0, 10, 11, 20))
    assert _apart(crop(11, 20, 11, 20), base)  # either order
    assert _apart(base, crop(11, 20, 5, 15))  # apart in rows, overlapping in columns
