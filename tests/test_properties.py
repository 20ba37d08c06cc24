"""Property-based tests (hypothesis) of the pure parts.

Pyramids invert and keep their shapes, PCA keeps projections bounded, the vote
keeps a constant appearance constant (its weights sum to one), centroid alignment
undoes a translation, colour spaces round-trip, option parsing accepts exactly
what it documents. Few examples each, no deadline: the default run stays fast.
"""

from __future__ import annotations

import argparse
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from imagemap import validate
from imagemap.align import centroid_shift, translate
from imagemap.core.engine import EngineParams, Mapping, synthesize, uniform_levels
from imagemap.core.pyramid import (
    collapse_laplacian,
    expand,
    gaussian_pyramid,
    laplacian_pyramid,
    level_shapes,
    mask_pyramid,
)
from imagemap.depth.guides import to_rgb, to_ycbcr
from imagemap.io import InputError, validate_depth

FAST = settings(
    max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow], derandomize=True
)

unit_floats = st.floats(0.0, 1.0, allow_nan=False, width=32)


@st.composite
def images(draw, max_side=40, channels=(None, 1, 3)):
    h = draw(st.integers(1, max_side))
    w = draw(st.integers(1, max_side))
    c = draw(st.sampled_from(channels))
    shape = (h, w) if c is None else (h, w, c)
    return draw(arrays(np.float32, shape, elements=unit_floats))


# -- pyramids ----------------------------------------------------------------------------------


@FAST
@given(images(), st.integers(1, 4))
def test_laplacian_pyramid_round_trip(image, levels):
    pyramid = laplacian_pyramid(image, levels)
    assert len(pyramid) == levels
    np.testing.assert_allclose(collapse_laplacian(pyramid), image, atol=1e-5)


@FAST
@given(images(), st.integers(1, 5))
def test_pyramid_shapes_follow_level_shapes(image, levels):
    shapes = [g.shape[:2] for g in gaussian_pyramid(image, levels)]
    assert shapes == level_shapes(image.shape[:2], levels)
    assert [b.shape for b in laplacian_pyramid(image, levels)] == [
        g.shape for g in gaussian_pyramid(image, levels)
    ]


@FAST
@given(st.integers(1, 30), st.integers(1, 30), unit_floats, st.integers(1, 4))
def test_constant_image_stays_constant_in_the_gaussian_pyramid(h, w, value, levels):
    for level in gaussian_pyramid(np.full((h, w), value, np.float32), levels):
        np.testing.assert_allclose(level, value, atol=1e-5)


@FAST
@given(images(channels=(None,)), st.integers(2, 60), st.integers(2, 60))
def test_expand_stays_within_the_coarse_range(coarse, extra_h, extra_w):
    shape = (2 * coarse.shape[0] - 1 + extra_h % 2, 2 * coarse.shape[1] - 1 + extra_w % 2)
    fine = expand(coarse, shape)
    assert fine.shape == shape
    assert fine.min() >= coarse.min() - 1e-6 and fine.max() <= coarse.max() + 1e-6


@FAST
@given(st.integers(2, 30), st.integers(2, 30), st.integers(1, 4))
def test_full_mask_stays_full(h, w, levels):
    assert all(level.all() for level in mask_pyramid(np.ones((h, w), bool), levels))


# -- PCA: projections are bounded by the data --------------------------------------------------


@FAST
@given(
    st.integers(5, 60),
    st.integers(2, 20),
    st.integers(1, 8),
    st.integers(0, 2**32 - 1),
)
def test_pca_basis_is_orthonormal_and_projection_bounded(n, dim, keep, seed):
    from imagemap.core.solver import _fit_pca as fit

    keep = min(keep, dim)
    rng = np.random.default_rng(seed)
    samples = rng.normal(size=(n, dim)).astype(np.float32) * rng.uniform(0.1, 3, dim)
    mean, basis = fit(samples, keep, rng)
    assert basis.shape == (dim, keep)
    np.testing.assert_allclose(basis.T @ basis, np.eye(keep), atol=1e-3)
    centred = samples - mean
    projected = centred @ basis
    # A projection onto orthonormal directions never lengthens a vector...
    assert np.all(
        np.linalg.norm(projected, axis=1) <= np.linalg.norm(centred, axis=1) * (1 + 1e-4) + 1e-5
    )
    # ... and the kept directions hold at least their share of the variance.
    kept = float(np.square(projected).sum())
    total = float(np.square(centred).sum())
    assert kept >= total * keep / dim * (1 - 1e-3) - 1e-4


# -- the vote: a constant appearance stays constant --------------------------------------------


@settings(max_examples=8, deadline=None, derandomize=True)
@given(
    st.integers(12, 24),
    st.integers(12, 24),
    st.lists(unit_floats, min_size=1, max_size=3),
    st.sampled_from(["exact", "patchmatch"]),
    st.integers(0, 1000),
)
def test_constant_appearance_votes_to_the_same_constant(h, w, values, backend, seed):
    rng = np.random.default_rng(seed)
    guide = rng.random((h, w, 1)).astype(np.float32)
    appearance = np.broadcast_to(np.asarray(values, np.float32), (h, w, len(values))).copy()
    exemplar = Mapping(guide=guide, appearance=appearance)
    query = Mapping(guide=np.roll(guide, 2, axis=1))
    params = EngineParams(
        levels=uniform_levels((5,), max_iterations=2),
        backend=backend,
        guide_weights=(1.0,),
        appearance_weights=(1.0,) * len(values),
    )
    result = synthesize([query], [[exemplar]], params, seed=seed)
    # Each pixel is a weighted mean of equal values: only weights summing to one keep it.
    np.testing.assert_allclose(result.appearance[0], appearance, atol=1e-5)


# -- centroid alignment ------------------------------------------------------------------------


@FAST
@given(
    st.integers(20, 40),
    st.integers(20, 40),
    st.integers(-5, 5),
    st.integers(-5, 5),
    st.integers(0, 2**32 - 1),
)
def test_centroid_shift_undoes_a_translation(h, w, dy, dx, seed):
    rng = np.random.default_rng(seed)
    mask = np.zeros((h, w), bool)
    y0, x0 = rng.integers(6, h // 2), rng.integers(6, w // 2)
    mask[y0 : y0 + rng.integers(2, 8), x0 : x0 + rng.integers(2, 8)] = True
    moved = translate(mask.astype(np.float32), (dy, dx), (h, w)) > 0.5
    assume(moved.sum() == mask.sum())  # the object stayed in the frame
    np.testing.assert_allclose(centroid_shift(mask, moved), (dy, dx), atol=1e-9)
    back = translate(moved.astype(np.float32), centroid_shift(moved, mask), (h, w)) > 0.5
    np.testing.assert_array_equal(back, mask)


# -- colour spaces -----------------------------------------------------------------------------


@FAST
@given(
    arrays(
        np.float32,
        st.tuples(st.integers(1, 8), st.integers(1, 8), st.just(3)),
        elements=unit_floats,
    )
)
def test_ycbcr_round_trip(rgb):
    ycbcr = to_ycbcr(rgb)
    assert ycbcr.min() >= 0.0 and ycbcr.max() <= 1.0
    np.testing.assert_allclose(to_rgb(ycbcr), rgb, atol=2e-5)


# -- depth validation --------------------------------------------------------------------------


@FAST
@given(
    arrays(
        np.float32,
        st.tuples(st.integers(8, 20), st.integers(8, 20)),
        elements=st.one_of(st.just(np.nan), st.floats(0.0, 1e6, width=32)),
    )
)
def test_validate_depth_gives_finite_non_negative_depth_or_refuses(depth):
    try:
        out = validate_depth(depth)
    except InputError as exc:
        assert "no foreground" in str(exc)
        assert not np.any(np.nan_to_num(depth) > 0)
        return
    assert out.dtype == np.float32 and np.all(np.isfinite(out)) and np.all(out >= 0)
    np.testing.assert_array_equal(out > 0, np.nan_to_num(depth) > 0)


# -- option parsing ----------------------------------------------------------------------------


@FAST
@given(st.integers(-(10**6), 10**6))
def test_integer_options_accept_exactly_their_range(value):
    for parse, minimum in ((validate.positive_int, 1), (validate.non_negative_int, 0)):
        if value >= minimum:
            assert parse(str(value)) == value
        else:
            with pytest.raises(argparse.ArgumentTypeError):
                parse(str(value))


@FAST
@given(st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=6)))
def test_float_option_accepts_finite_non_negative_only(value):
    text = value if isinstance(value, str) else repr(value)
    try:
        number = float(text)
    except ValueError:
        number = None
    if number is not None and math.isfinite(number) and number >= 0:
        assert validate.non_negative_float(text) == number
    else:
        with pytest.raises(argparse.ArgumentTypeError):
            validate.non_negative_float(text)


@FAST
@given(st.one_of(st.booleans(), st.floats(), st.text(max_size=4), st.none()))
def test_api_integers_refuse_non_integers(value):
    with pytest.raises(InputError, match="^m:"):
        validate.check_int("m", value, minimum=1)


@FAST
@given(st.tuples(st.integers(0, 255), st.integers(0, 255), st.integers(0, 255)))
def test_background_colour_round_trip(rgb):
    from imagemap.cli.options import parse_colour

    text = "#" + "".join(f"{c:02x}" for c in rgb)
    assert parse_colour(text) == tuple(c / 255 for c in rgb)
    assert parse_colour(text.upper().replace("#", "#")) == tuple(c / 255 for c in rgb)


@FAST
@given(st.integers(16, 4000), st.integers(16, 4000))
def test_data_gen_size_round_trip(width, height):
    from data_gen.__main__ import parse_size

    assert parse_size(f"{width}x{height}") == (width, height)
    with pytest.raises(argparse.ArgumentTypeError):
        parse_size(f"{width}x")
