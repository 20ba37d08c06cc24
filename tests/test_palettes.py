"""One palette per part: a part copied from two examples is shifted into one example's colours."""

from __future__ import annotations

import numpy as np

from imagemap.depth.palettes import even_palettes, palette_clusters

SIZE = 64
SKIN_A, SHIRT_A = (0.62, 0.45, 0.56), (0.30, 0.62, 0.40)
SKIN_B, SHIRT_B = (0.50, 0.48, 0.57), (0.20, 0.30, 0.70)
STRIPE = (0.15, 0.52, 0.50)
SHIRT_NEAR_A = (0.26, 0.58, 0.44)  # a shirt of nearly A's colour
HAIR = (0.15, 0.50, 0.55)


def _object():
    mask = np.zeros((SIZE, SIZE), bool)
    mask[4:60, 12:52] = True
    return mask


def _example(skin, shirt, seed, neckline=32):
    """Skin above the neckline, shirt below, with a little smooth grain."""
    rng = np.random.default_rng(seed)
    image = np.empty((SIZE, SIZE, 3), np.float32)
    image[:neckline] = skin
    image[neckline:] = shirt
    yy, xx = np.mgrid[0:SIZE, 0:SIZE]
    image += (0.01 * np.sin(xx / 5.0 + seed) * np.cos(yy / 7.0))[..., None]
    image += rng.normal(0, 0.004, image.shape).astype(np.float32)
    return image


def _identity(example_of):
    source = np.zeros((SIZE, SIZE, 3), np.int32)
    source[..., 0] = example_of
    source[..., 1], source[..., 2] = np.mgrid[0:SIZE, 0:SIZE]
    return source


def _shift_with_b_in(a, b, rows, cols):
    """even_palettes of a copy from A with a box of B (rows, cols) on the same object."""
    mask = _object()
    example_of = np.zeros((SIZE, SIZE), np.int32)
    example_of[rows, cols] = 1
    return even_palettes([a, b], [mask, mask], _identity(example_of), mask)


def _unshifted(shift):
    return shift is None or np.abs(shift).max() == 0


def test_palette_clusters_find_the_parts_of_a_plain_example():
    mask = _object()
    labels, means = palette_clusters(_example(SKIN_A, SHIRT_A, 0), mask)
    # However the grain splits the colours, the skin and the shirt end up in one cluster each.
    assert len(np.unique(labels[mask])) == 2
    assert labels[10, 20] != labels[50, 20]
    np.testing.assert_allclose(means[labels[10, 20]], SKIN_A, atol=0.01)


def test_the_smaller_share_of_a_part_takes_the_larger_share_s_colours():
    mask = _object()
    a, b = _example(SKIN_A, SHIRT_A, 0), _example(SKIN_B, SHIRT_B, 1)
    example_of = np.zeros((SIZE, SIZE), np.int32)
    example_of[4:32, 40:52] = 1  # a strip of B's skin on the right of the face
    shift = even_palettes([a, b], [mask, mask], _identity(example_of), mask)
    assert shift is not None
    from_b = example_of == 1
    # B's skin is moved onto A's: the face is one skin.
    np.testing.assert_allclose(shift[from_b].mean(0), np.subtract(SKIN_A, SKIN_B), atol=0.01)
    # A's pixels keep their colours.
    assert np.abs(shift[mask & ~from_b]).max() == 0


def test_a_part_in_the_place_of_another_s_part_of_another_colour_is_not_matched():
    # B wears its shirt on top and its skin below: B's shirt covers A's skin's place,
    # but A's shirt is far nearer in colour to it. A shirt is not shifted into a skin
    # tone, nor a skin into a shirt's colour.
    a = _example(SKIN_A, SHIRT_A, 0)
    b = _example(SHIRT_NEAR_A, SKIN_B, 1)
    # B's shirt among A's skin
    assert _unshifted(_shift_with_b_in(a, b, slice(4, 32), slice(40, 52)))


def test_a_thin_pattern_is_not_recoloured():
    # Dark one-pixel stripes in B's skin: they are not a part of their own (shifting one
    # colour of a pattern and not the other would change its contrast), and far from the
    # skin's colours, so they keep their colour while the skin around them is shifted.
    mask = _object()
    a = _example(SKIN_A, SHIRT_A, 0)
    b = _example(SKIN_B, SHIRT_B, 1)
    stripes = np.zeros((SIZE, SIZE), bool)
    stripes[6:32:6, 36:52] = True
    b[stripes] = STRIPE
    example_of = np.zeros((SIZE, SIZE), np.int32)
    example_of[4:32, 40:52] = 1
    shift = even_palettes([a, b], [mask, mask], _identity(example_of), mask)
    assert shift is not None
    from_b = example_of == 1
    assert np.abs(shift[stripes & from_b]).max() < 0.01
    np.testing.assert_allclose(
        shift[from_b & ~stripes].mean(0), np.subtract(SKIN_A, SKIN_B), atol=0.01
    )


def test_a_pattern_is_not_recoloured():
    # B's upper half is a pattern of two-pixel stripes in two tones, both nearer to A's
    # skin than to its shirt, the darker joined into one piece as large as a part;
    # shifting one tone into A's skin and not the other would change the pattern's
    # contrast, so neither moves: a thin piece is no part.
    a = _example(SKIN_A, SHIRT_A, 0)
    b = _example(SKIN_B, SHIRT_B, 1)
    b[0:32:4] = b[1:32:4] = (0.42, 0.46, 0.57)
    b[4:32, 12:14] = (0.42, 0.46, 0.57)  # the stripes joined into one large piece: a comb
    assert _unshifted(_shift_with_b_in(a, b, slice(4, 32), slice(40, 52)))


def test_a_part_that_mostly_lies_elsewhere_is_not_matched():
    # A: hair, skin, shirt from top to bottom. B's skin is a narrow strip from top to
    # bottom: under half of it lies where A has skin, so it is not the face's part, though
    # A's skin is where it overlaps most and nearest in colour.
    a = _example(SKIN_A, SHIRT_A, 0, neckline=42)
    a[:18] = HAIR
    b = _example(SHIRT_B, SHIRT_B, 1)
    b[:, 12:20] = SKIN_B
    assert _unshifted(_shift_with_b_in(a, b, slice(18, 42), slice(12, 20)))


def test_one_example_changes_nothing_and_the_same_seed_gives_the_same_shift():
    mask = _object()
    a, b = _example(SKIN_A, SHIRT_A, 0), _example(SKIN_B, SHIRT_B, 1)
    assert even_palettes([a], [mask], _identity(np.zeros((SIZE, SIZE), np.int32)), mask) is None
    example_of = np.zeros((SIZE, SIZE), np.int32)
    example_of[4:32, 40:52] = 1
    first = even_palettes([a, b], [mask, mask], _identity(example_of), mask, seed=3)
    again = even_palettes([a, b], [mask, mask], _identity(example_of), mask, seed=3)
    np.testing.assert_array_equal(first, again)
