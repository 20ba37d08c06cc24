"""Small features: found from an exemplar's colours, and copied whole where the copy cut them."""

from __future__ import annotations

import numpy as np
import pytest

from imagemap.core.blend import copy_through
from imagemap.depth.completion import DOUBLE_SHIFT, complete_features, small_features
from imagemap.depth.config import Completion

SKIN = 0.5


def _skin(size=120):
    return np.full((size, size, 1), SKIN, np.float32)


def _identity(size):
    source = np.zeros((size, size, 3), np.int32)
    source[..., 1], source[..., 2] = np.mgrid[0:size, 0:size]
    return source


def _exemplar_with_lips(size=80):
    """Flat skin with dark lips (4 x 12 px) at rows 38-41, columns 34-45."""
    exemplar = _skin(size)
    exemplar[38:42, 34:46] = 0.2
    return exemplar


def test_small_features_are_compact_sharp_and_rare():
    image = _skin()
    image[20:24, 20:34] = 0.15  # a brow: the one feature
    yy, xx = np.mgrid[0:120, 0:120]
    image[..., 0] += 0.12 * np.exp(-((yy - 70) ** 2 + (xx - 30) ** 2) / (2 * 6.0**2))  # a blush
    image[100:103, 10:110] = 0.1  # a long stripe
    for y in (40, 55, 70):  # a texture: nine equal squares
        for x in (70, 85, 100):
            image[y : y + 5, x : x + 5] = 0.9
    labels, n = small_features(image, np.ones((120, 120), bool))
    assert n == 1
    ys, xs = np.nonzero(labels)
    assert (ys.min(), ys.max(), xs.min(), xs.max()) == (20, 23, 20, 33)


def test_a_feature_ends_at_an_edge_on_one_ground_or_on_two():
    # Two parts meeting at a straight edge (skin and cloth), a dark mark on each
    # side's own ground and one across the edge: each ends at an edge all around, of a
    # colour found nowhere near it, so all three are features (the one across the edge
    # since its grounds may be of several colours, as an eye across a fish's bands).
    image = _skin()
    image[:, 60:] = 0.8
    image[30:34, 20:28] = 0.2
    image[60:64, 56:64] = 0.2
    image[90:94, 85:93] = 0.2
    labels, n = small_features(image, np.ones((120, 120), bool))
    assert n == 3
    assert labels[31, 23] and labels[91, 88] and labels[61, 60]


def _banded(size=120, period=16):
    """Vertical bands, dark and light, 8 px each with soft edges (a fish's bars)."""
    wave = np.tanh(2.0 * np.sin(2 * np.pi * np.arange(size) / period))
    image = np.empty((size, size, 1), np.float32)
    image[...] = (0.475 + 0.125 * wave)[None, :, None]
    return image


def _disc(image, y, x, radius, value):
    yy, xx = np.mgrid[0 : image.shape[0], 0 : image.shape[1]]
    image[np.hypot(yy - y, xx - x) <= radius] = value


def test_an_eye_across_bands_is_a_feature():
    # A white disc with a dark pupil across three bands: its ground is two colours, so
    # the one-ground test refuses it, but it ends at an edge all around and nothing of
    # its colour is near. (Before grounds of several colours it was no feature, and
    # a copy could cut it freely: the 2048x1536 fish's eye came out as an orange fleck.)
    image = _banded(period=12)
    _disc(image, 60, 60, 8, 0.95)
    _disc(image, 60, 60, 3, 0.05)
    labels, n = small_features(image, np.ones((120, 120), bool))
    assert n == 1
    assert labels[60, 60] and labels[60, 67] and not labels[60, 70]


def test_on_bands_a_colour_found_nearby_is_a_texture_not_a_feature():
    # Two equal discs, 13 px wide and 11 px apart, on the bands: each has the other's
    # colour within two of its widths (rare_reach), as a check among checks or a
    # stripe's piece between others. Looked for within one width only, each is alone.
    # On one ground (plain skin) the same pair is two features, as two eyes are.
    everywhere = np.ones((120, 120), bool)
    for ground, expected in ((_banded(), 0), (_skin(), 2)):
        image = ground.copy()
        _disc(image, 60, 40, 6, 0.95)
        _disc(image, 60, 64, 6, 0.95)
        assert small_features(image, everywhere)[1] == expected
        assert small_features(image, everywhere, completion=Completion(rare_reach=1.0))[1] == 2


def test_a_brow_touching_a_larger_part_is_a_feature_of_its_own():
    # A dark brow touching a long band (a fringe of hair) is one component with it,
    # too wide to be a feature; cut at the colour step between them, the brow is one.
    # Of the band's colour it is part of the band, and no feature.
    for brow, expected in ((0.1, 1), (0.3, 0)):
        image = _skin()
        image[16:20, 10:110] = 0.3
        image[20:24, 40:56] = brow
        labels, n = small_features(image, np.ones((120, 120), bool))
        assert n == expected
        if n:
            ys, xs = np.nonzero(labels)
            assert (ys.min(), ys.max(), xs.min(), xs.max()) == (20, 23, 40, 55)


def test_an_eye_cut_from_a_larger_part_keeps_its_iris():
    image = _skin()
    image[16:20, 10:110] = 0.3
    image[20:28, 40:56] = 0.9  # an eye's white touching the band
    image[22:26, 45:51] = 0.1  # its iris: a piece of its own, inside the white
    image[23:25, 47:49] = 0.25  # and its pupil, inside the iris
    labels, n = small_features(image, np.ones((120, 120), bool))
    assert n == 1
    assert labels[24, 48] and (labels > 0).sum() == 8 * 16


def test_a_one_pixel_line_cut_from_a_larger_part_is_no_feature():
    image = _skin()
    image[16:20, 10:110] = 0.3
    image[20:21, 40:56] = 0.1  # a line where two parts meet, not a mark
    assert small_features(image, np.ones((120, 120), bool))[1] == 0
    image[20:22, 40:56] = 0.1
    assert small_features(image, np.ones((120, 120), bool))[1] == 1


def test_a_mark_cut_by_the_outline_is_no_feature():
    # The same long dark mark well inside the object and 3 px from its outline, where
    # what surrounds it on one side is outside: a part's corner, not a feature.
    for top, expected in ((100, 1), (23, 0)):
        image = _skin(240)
        image[top : top + 4, 100:140] = 0.2
        mask = np.ones((240, 240), bool)
        mask[:20] = False
        assert small_features(image, mask)[1] == expected


def test_five_squares_are_a_texture_and_four_are_features():
    for count, expected in ((4, 4), (5, 0)):
        image = _skin()
        for i in range(count):
            image[20 + 20 * i : 25 + 20 * i, 50:55] = 0.9
        assert small_features(image, np.ones((120, 120), bool))[1] == expected


def test_a_cut_feature_is_copied_whole_where_the_pieces_were():
    exemplar = _exemplar_with_lips()
    features = [small_features(exemplar, np.ones((80, 80), bool))]
    assert features[0][1] == 1
    source = _identity(80)
    # The right half of the lips' place copies skin from 6 px further right: half lips.
    source[30:50, 40:60, 2] += 6
    cut = copy_through([exemplar], source)
    assert (cut < 0.3).sum() == 4 * 6
    mask = np.ones((80, 80), bool)
    completed_source, completed = complete_features([exemplar], source, features, mask, [mask])
    assert completed == 1
    whole = copy_through([exemplar], completed_source)
    np.testing.assert_array_equal(whole[36:44, 32:48], exemplar[36:44, 32:48])
    # Nothing else was touched.
    changed = (completed_source != source).any(-1)
    assert not changed[:35].any() and not changed[45:].any()


def test_whole_copies_and_stray_fragments_are_left_alone():
    exemplar = _exemplar_with_lips()
    features = [small_features(exemplar, np.ones((80, 80), bool))]
    mask = np.ones((80, 80), bool)
    whole = _identity(80)
    assert complete_features([exemplar], whole, features, mask, [mask])[1] == 0
    fragment = _identity(80)
    fragment[30:50, 36:60, 2] += 10  # only 2 of the 12 columns copied: a fragment
    assert 2 / 12 < Completion().partial_share
    assert complete_features([exemplar], fragment, features, mask, [mask])[1] == 0


def test_a_piece_beside_a_whole_feature_of_its_colour_is_a_stray():
    # Two exemplars with the same lips: the map shows the first's whole, and 8 px
    # above them half of the second's (a piece of a second mouth).
    exemplars = [_exemplar_with_lips(), _exemplar_with_lips()]
    features = [small_features(x, np.ones((80, 80), bool)) for x in exemplars]
    mask = np.ones((80, 80), bool)
    source = _identity(80)
    source[30:34, 34:52, 0] = 1
    source[30:34, 34:52, 1] += 8
    source[30:34, 40:52, 2] += 6
    shown = copy_through(exemplars, source)
    assert (shown[30:34] < 0.3).sum() == 4 * 6 and (shown[38:42] < 0.3).sum() == 4 * 12
    assert complete_features(exemplars, source, features, mask, [mask, mask])[1] == 0
    # Without the whole lips below, the same piece is completed.
    alone = source.copy()
    alone[36:44, :, 1] -= 20
    assert (copy_through(exemplars, alone)[36:44] < 0.3).sum() == 0
    assert complete_features(exemplars, alone, features, mask, [mask, mask])[1] == 1


def test_the_most_complete_copy_is_completed_and_a_lesser_one_beside_it_left():
    # Two exemplars with the same lips. The map copies two thirds of the second's at
    # their place and, 8 px above, a quarter of the first's: the two thirds are
    # completed, and the quarter, now beside whole lips of its colour, is left.
    exemplars = [_exemplar_with_lips(), _exemplar_with_lips()]
    features = [small_features(x, np.ones((80, 80), bool)) for x in exemplars]
    mask = np.ones((80, 80), bool)
    source = _identity(80)
    source[36:44, :, 0] = 1
    source[36:44, 42:60, 2] += 6  # columns 34-41 of 34-45: two thirds
    source[30:34, 34:48, 1] += 8  # rows 38-41 of the first exemplar
    source[30:34, 37:48, 2] += 9  # only columns 34-36: a quarter
    shown = copy_through(exemplars, source)
    assert (shown[30:34] < 0.3).sum() == 4 * 3 and (shown[38:42] < 0.3).sum() == 4 * 8
    assert Completion().partial_share <= 0.25
    completed_source, completed = complete_features(exemplars, source, features, mask, [mask, mask])
    assert completed == 1
    result = copy_through(exemplars, completed_source)
    np.testing.assert_array_equal(result[36:44, 32:48], exemplars[1][36:44, 32:48])
    assert (result[30:34] < 0.3).sum() == 4 * 3


def test_a_feature_is_not_completed_over_another_part():
    exemplar = _exemplar_with_lips()
    exemplar[:, 50:] = 0.9  # a different part starts 4 px right of the lips
    features = [small_features(exemplar, np.ones((80, 80), bool))]
    mask = np.ones((80, 80), bool)
    source = _identity(80)
    source[30:50, 40:, 2] -= 30  # the map's right side copies skin from the left
    shown = copy_through([exemplar], source)
    assert (shown[38:42, 40:48] == SKIN).all()
    # Completing would bring the other part's colour into the rim only if the rim
    # reached it; here it does not, so the lips are completed ...
    assert complete_features([exemplar], source, features, mask, [mask])[1] == 1
    # ... but where the map shows the other part right beside the cut lips, they are not.
    other = source.copy()
    other[30:50, 41:, 2] = 60
    assert complete_features([exemplar], other, features, mask, [mask])[1] == 0


def test_a_feature_must_land_inside_the_object():
    exemplar = _exemplar_with_lips()
    features = [small_features(exemplar, np.ones((80, 80), bool))]
    source = _identity(80)
    source[30:50, 40:60, 2] += 6
    mask = np.ones((80, 80), bool)
    query_mask = mask.copy()
    query_mask[:, 44:] = False  # the query's outline cuts through where the lips would go
    assert complete_features([exemplar], source, features, query_mask, [mask])[1] == 0


def test_shading_below_the_contrast_is_no_feature():
    threshold = Completion().feature_contrast
    image = _skin()
    image[20:24, 20:34] = SKIN - 0.8 * threshold
    assert small_features(image, np.ones((120, 120), bool))[1] == 0
    image[20:24, 20:34] = SKIN - 1.5 * threshold
    assert small_features(image, np.ones((120, 120), bool))[1] == 1


def test_mismatched_inputs_are_refused_with_their_shapes():
    exemplar = _exemplar_with_lips()
    with pytest.raises(ValueError, match=r"\(80, 80, 1\).*\(60, 60\)"):
        small_features(exemplar, np.ones((60, 60), bool))
    features = [small_features(exemplar, np.ones((80, 80), bool))]
    mask = np.ones((80, 80), bool)
    with pytest.raises(ValueError, match="one of each per exemplar"):
        complete_features([exemplar, exemplar], _identity(80), features, mask, [mask])
    with pytest.raises(ValueError, match=r"\(80, 80, 3\).*\(40, 40\)"):
        complete_features([exemplar], _identity(80), features, mask[:40, :40], [mask])


def _textured_skin_with_lips(size=80, seed=5):
    """Lips on a faintly textured skin (the texture makes offsets tell apart)."""
    rng = np.random.default_rng(seed)
    exemplar = _exemplar_with_lips(size) + 0.01 * rng.standard_normal((size, size, 1))
    return exemplar.astype(np.float32)


def test_a_skipped_feature_is_copied_where_its_surroundings_were():
    # The map copies the skin around the lips at offset 0 but fills the lips' place
    # with skin from elsewhere: none of the lips copied, all of their ring.
    exemplar = _textured_skin_with_lips()
    features = [small_features(exemplar, np.ones((80, 80), bool))]
    assert features[0][1] == 1
    mask = np.ones((80, 80), bool)
    source = _identity(80)
    source[37:43, 33:47, 1] += 25  # the lips' place from skin 25 rows below
    assert (copy_through([exemplar], source) < 0.3).sum() == 0
    completed_source, completed = complete_features([exemplar], source, features, mask, [mask])
    assert completed == 1
    whole = copy_through([exemplar], completed_source)
    np.testing.assert_array_equal(whole[38:42, 34:46], exemplar[38:42, 34:46])
    # Skin copied from far away around the place (no ring copied): nothing to complete.
    elsewhere = _identity(80)
    elsewhere[28:52, 22:58, 1] += 25
    assert complete_features([exemplar], elsewhere, features, mask, [mask])[1] == 0


def test_a_skipped_feature_is_not_pasted_over_what_the_map_already_shows_there():
    # The lips' ring is copied, and their place is filled from a second exemplar whose
    # dark mark there (an eye, say) its feature detection did not find: the map
    # already shows something at that place, and the lips are not pasted over it.
    lips = _textured_skin_with_lips()
    other = _textured_skin_with_lips(seed=6)
    other[38:42, 34:46] = 0.35  # a mark no detection labelled
    mask = np.ones((80, 80), bool)
    features = [small_features(lips, mask), (np.zeros((80, 80), np.int32), 0)]
    source = _identity(80)
    source[38:42, 34:46, 0] = 1  # the lips' place copies the mark
    assert (copy_through([lips, other], source)[38:42, 34:46] == other[38:42, 34:46]).all()
    completed_source, completed = complete_features(
        [lips, other], source, features, mask, [mask, mask]
    )
    assert completed == 0
    np.testing.assert_array_equal(completed_source, source)
    # The same place filled from the second exemplar's plain skin: the lips are drawn.
    plain = source.copy()
    plain[38:42, 34:46, 1] += 25
    assert complete_features([lips, other], plain, features, mask, [mask, mask])[1] == 1


def _exemplar_with_eye(size=80, radius=6):
    """Flat skin with a dark disc (an eye) of the given radius at (40, 40)."""
    exemplar = _skin(size)
    yy, xx = np.mgrid[0:size, 0:size]
    exemplar[(yy - 40) ** 2 + (xx - 40) ** 2 <= radius**2] = 0.1
    return exemplar


def test_a_feature_copied_twice_over_itself_is_drawn_once():
    # The map copies the eye (rows 34-46) in place down to row 41, then rows 42-47 from
    # 5 rows higher up: rows 37-42 of the eye again below its upper part, an "8".
    # Neither copy is whole.
    exemplar = _exemplar_with_eye()
    features = [small_features(exemplar, np.ones((80, 80), bool))]
    assert features[0][1] == 1
    eye = int((exemplar < 0.3).sum())
    mask = np.ones((80, 80), bool)
    source = _identity(80)
    source[42:48, :, 1] -= 5
    doubled = copy_through([exemplar], source)
    assert (doubled < 0.3).sum() > eye  # more eye than the eye has
    result_source, _ = complete_features([exemplar], source, features, mask, [mask])
    result = copy_through([exemplar], result_source)
    np.testing.assert_array_equal(result, exemplar)  # one eye, in its place
    # Displaced by less than a quarter of the eye's width (13 px): a ragged edge, not
    # a double, left to the seams.
    ragged = _identity(80)
    ragged[42:48, :, 1] -= 2
    assert 2 < DOUBLE_SHIFT * 13
    kept, _ = complete_features([exemplar], ragged, features, mask, [mask])
    np.testing.assert_array_equal(kept[42:48], ragged[42:48])


def test_nearest_host_distance_equals_the_nine_gathers():
    # The kernel must give, bit for bit, the smallest distance to the hosts of a pixel's
    # cell and of the eight around it (clipped at the borders), as nine gathers would.
    from imagemap.core.kernels import nearest_host_distance

    rng = np.random.default_rng(3)
    colours = rng.random((37, 29, 3)).astype(np.float32)
    host = rng.random((9, 7, 3)).astype(np.float32)
    cell_y = np.minimum(np.arange(37) // 4, 8)
    cell_x = np.minimum(np.arange(29) // 4, 6)
    expected = np.full((37, 29), np.inf, np.float32)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            ys = np.clip(cell_y + dy, 0, 8)
            xs = np.clip(cell_x + dx, 0, 6)
            gap = np.sqrt(((colours - host[ys[:, None], xs[None, :]]) ** 2).sum(-1))
            np.minimum(expected, gap, out=expected)
    found = nearest_host_distance(colours, host, cell_y.astype(np.int64), cell_x.astype(np.int64))
    assert found.dtype == np.float32
    np.testing.assert_array_equal(found, expected)
    # and a pixel equal to a neighbouring cell's host is at distance 0
    colours[0, 0] = host[1, 1]
    assert (
        nearest_host_distance(colours, host, cell_y.astype(np.int64), cell_x.astype(np.int64))[0, 0]
        == 0
    )


def test_neighbour_counts_from_the_pair_table_are_the_k_d_trees(monkeypatch):
    # The table of all pairs (used up to PAIR_TABLE_POINTS, no scipy.spatial import) must
    # count exactly what cKDTree.query_ball_point counts, points at the radius included.
    from scipy.spatial import cKDTree

    from imagemap.depth import completion

    rng = np.random.default_rng(0)
    points = rng.random((400, 3)) * 0.3
    points[1] = points[0] + [0.07, 0.0, 0.0]  # at the radius: the boundary case
    points[2] = points[0] + [0.0, 0.07 * (1 - 1e-6), 0.0]
    radius = 0.07
    expected = cKDTree(points).query_ball_point(points, r=radius, return_length=True)
    counts = completion._neighbour_counts(points, radius)
    assert len(points) <= completion.PAIR_TABLE_POINTS
    assert counts.min() >= 1 and counts.max() > 3  # the sample has neighbours to count
    np.testing.assert_array_equal(counts, expected)
    monkeypatch.setattr(completion, "PAIR_TABLE_POINTS", 100)  # the k-d tree's route
    np.testing.assert_array_equal(completion._neighbour_counts(points, radius), expected)


def test_joined_components_are_csgraphs_components_in_its_numbering(monkeypatch):
    # The doubled-grid labelling (no scipy.sparse import) must give the components of
    # csgraph.connected_components on the pixels in raster order, numbered alike: the
    # wide components' pieces, and so the features, keep their order and their labels.
    from scipy.sparse import coo_matrix, csgraph

    from imagemap.depth import completion
    from imagemap.depth.completion import _joined_components

    rng = np.random.default_rng(1)
    for trial in range(6):
        shape = (int(rng.integers(5, 40)), int(rng.integers(5, 40)))
        region = rng.random(shape) < (0.5 if trial % 2 else 0.95)
        region[:2] = False  # a box smaller than the picture
        across = rng.random((shape[0], shape[1] - 1)) < 0.6
        down = rng.random((shape[0] - 1, shape[1])) < 0.6
        index = np.full(shape, -1)
        index[region] = np.arange(int(region.sum()))
        edges = [
            (index[a][join], index[b][join])
            for a, b, links in (
                (np.s_[:, :-1], np.s_[:, 1:], across),
                (np.s_[:-1, :], np.s_[1:, :], down),
            )
            for join in [links & region[a] & region[b]]
        ]
        first = np.concatenate([f for f, _ in edges])
        second = np.concatenate([s for _, s in edges])
        size = int(region.sum())
        graph = coo_matrix((np.ones(len(first), np.int8), (first, second)), (size, size))
        m, which = csgraph.connected_components(graph, directed=False)
        expected = np.zeros(shape, np.int32)
        expected[region] = which + 1
        labels, count = _joined_components(region, across, down)
        assert count == m and m > 3
        np.testing.assert_array_equal(labels, expected)
        with monkeypatch.context() as patch:  # the large regions' route: csgraph itself
            patch.setattr(completion, "GRID_LABEL_PIXELS", 0)
            labels, count = _joined_components(region, across, down)
        assert count == m
        np.testing.assert_array_equal(labels, expected)
    empty = np.zeros((3, 4), bool)
    labels, none = _joined_components(empty, np.ones((3, 3), bool), np.ones((2, 4), bool))
    assert none == 0 and not labels.any()


def test_small_features_of_filled_colours_need_no_second_fill():
    """An example's YCbCr as the copy stage makes it (example_ycbcr: its background the
    nearest object colour) gives the same features with ``filled`` as without."""
    from imagemap import Example
    from imagemap.depth.guides import example_ycbcr

    yy, xx = np.mgrid[0:90, 0:110]
    mask = (yy - 45) ** 2 / 35**2 + (xx - 55) ** 2 / 48**2 < 1
    rng = np.random.default_rng(6)
    image = np.where(mask[..., None], [0.7, 0.5, 0.3], 0.0) + 0.02 * rng.random((90, 110, 3))
    image[40:46, 30:38] = [0.1, 0.1, 0.4]  # an eye
    image[20:23, 60:90] = [0.9, 0.9, 0.2]  # a stripe
    depth = np.where(mask, 1.0, 0.0).astype(np.float32)
    exemplar = example_ycbcr(Example.from_arrays("e", depth, np.clip(image, 0, 1)))
    labels, n = small_features(exemplar, mask)
    filled, m = small_features(exemplar, mask, filled=True)
    assert n == m >= 1 and np.array_equal(labels, filled)
