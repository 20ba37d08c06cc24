"""Detail: blur ratio, small features, seamless copying, the mode vote, pyramid depth."""

from __future__ import annotations

import inspect
from dataclasses import replace

import numpy as np
import pytest
from scipy import ndimage

from imagemap import Database, DepthConfig, Example, colorize
from imagemap.core.blend import coherent_edges, copy_through
from imagemap.core.poisson import seamless_copy
from imagemap.depth.config import PRESETS, Finish
from imagemap.depth.guides import (
    FINAL_RESEED,
    level_patch_sizes,
    pyramid_levels,
    silhouette_band,
)
from imagemap.metrics import (
    blur_ratio,
    feature_components,
    features_drawn,
    macro_part_transfer,
    source_labels,
)


def identity_source(shape, exemplar=0):
    source = np.zeros(shape + (3,), np.int32)
    source[..., 0] = exemplar
    source[..., 1], source[..., 2] = np.mgrid[0 : shape[0], 0 : shape[1]]
    return source


def random_source(rng, shape, reach):
    """A source map of random pixels: exemplar -1 (none), 0 or 1, and a source row and
    column within ``reach`` (rows, columns), drawn in that order."""
    return np.stack(
        [
            rng.integers(-1, 2, shape),
            rng.integers(0, reach[0], shape),
            rng.integers(0, reach[1], shape),
        ],
        axis=-1,
    ).astype(np.int32)


def test_blur_ratio_is_one_for_a_copy_and_less_for_a_blurred_copy():
    rng = np.random.default_rng(0)
    copy = rng.random((40, 50, 3)).astype(np.float32)
    mask = np.zeros((40, 50), bool)
    mask[5:35, 5:45] = True
    assert blur_ratio(copy, copy, mask) == pytest.approx(1.0)
    blurred = ndimage.gaussian_filter(copy, (1.0, 1.0, 0))
    assert blur_ratio(blurred, copy, mask) < 0.3
    # A colour offset is not blur: the fine band is unchanged.
    assert blur_ratio(np.clip(copy * 0.5 + 0.2, 0, 1), copy, mask) == pytest.approx(0.25, 1e-3)


def test_features_are_the_small_parts_and_missing_ones_are_seen():
    truth = np.full((60, 60, 3), 0.7, np.float32)
    labels = np.ones((60, 60), np.int32)
    for y, x in ((20, 20), (20, 40)):  # two eyes: two features of part 2
        truth[y - 2 : y + 3, x - 2 : x + 3] = 0.05
        labels[y - 2 : y + 3, x - 2 : x + 3] = 2
    mask = np.ones((60, 60), bool)
    assert [p for p, _ in feature_components(labels, mask)] == [2, 2]
    assert features_drawn(truth, truth, labels, mask) == (2, 2)
    # Shifted by two pixels: still drawn (tolerance); one eye erased: one missing.
    assert features_drawn(np.roll(truth, 2, axis=1), truth, labels, mask) == (2, 2)
    one_eye = truth.copy()
    one_eye[15:26, 35:46] = 0.7
    assert features_drawn(one_eye, truth, labels, mask) == (1, 2)
    # Smeared (a wide blur): the pattern is too weak and wide to correlate.
    assert features_drawn(ndimage.uniform_filter(truth, (15, 15, 1)), truth, labels, mask)[0] < 2


def test_macro_part_transfer_weights_parts_equally():
    labels = np.ones((10, 10), np.int32)
    labels[0, 0] = 2
    transferred = np.ones_like(labels)  # the one-pixel part 2 is wrong
    mask = np.ones((10, 10), bool)
    assert macro_part_transfer(transferred, labels, mask) == pytest.approx(0.5)
    assert np.mean(transferred == labels) == pytest.approx(0.99)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_seamless_copy_keeping_its_copies_gives_the_same_bytes(monkeypatch, dtype):
    """The blend keeps each shifted copy once gathered on small frames (KEEP_COPIES_PIXELS;
    in float32 where the inputs are): the same bytes as gathering every copy again, with
    a mask, edges kept, sources off the exemplars' edges and pixels without a source."""
    from imagemap.core import poisson

    rng = np.random.default_rng(3)
    exemplars = [rng.random((30, 40, 3)).astype(dtype) for _ in range(2)]
    source = random_source(rng, (36, 44), (30, 40))
    source[8:30, 6:40, 0] = 1  # a coherent block: its copy's own detail
    source[8:30, 6:40, 1:] = np.stack(np.mgrid[0:22, 0:34], axis=-1) + (4, 3)
    reference = rng.random((36, 44, 3)).astype(dtype)
    mask = np.zeros((36, 44), bool)
    mask[4:33, 3:42] = True

    def blend():
        return seamless_copy(
            exemplars, source, reference, scale=5.0, edge_support=0.3, edge_floor=0.01, mask=mask
        )

    assert 36 * 44 <= poisson.KEEP_COPIES_PIXELS
    kept = blend()
    monkeypatch.setattr(poisson, "KEEP_COPIES_PIXELS", 0)
    np.testing.assert_array_equal(kept, blend())


def test_seamless_copy_keeps_a_coherent_copy_and_hides_a_palette_seam():
    rng = np.random.default_rng(1)
    texture = ndimage.gaussian_filter(rng.standard_normal((48, 64, 1)), (1, 1, 0))
    dark, bright = 0.3 + 0.1 * texture, 0.7 + 0.1 * texture
    reference = np.full((48, 64, 1), 0.5)
    # One source, coherent everywhere: the copy comes back up to a constant.
    one = seamless_copy([dark], identity_source((48, 64)), reference, scale=1e4)
    assert np.ptp(one - dark) < 0.02
    # Two palettes meeting: no step at the seam, the texture kept on both sides.
    source = identity_source((48, 64))
    source[:, 32:, 0] = 1
    out = seamless_copy([dark, bright], source, reference, scale=6.0)
    horizontal, _ = coherent_edges(source)
    assert not horizontal[:, 31].any() and horizontal[:, 30].all()
    step = np.abs(out[:, 32] - out[:, 31]).mean()
    assert step < 0.05 < np.abs(copy_through([dark, bright], source)[:, 32] - dark[:, 31]).mean()
    fine = out[..., 0] - ndimage.gaussian_filter(out[..., 0], 3)
    fine_truth = texture[..., 0] - ndimage.gaussian_filter(texture[..., 0], 3)
    assert np.corrcoef(fine.ravel(), fine_truth.ravel())[0, 1] > 0.95
    # Pixels without a source keep the reference.
    none = seamless_copy([dark], identity_source((48, 64)) * 0 - 1, reference, scale=4.0)
    np.testing.assert_allclose(none, reference, atol=1e-6)


def test_colours_copied_beside_the_object_do_not_bleed_across_its_outline():
    # A narrow neck (columns 20..27) copied from one example's skin, the margin around
    # it from another example's shirt; the reference is the voted neck inside and the
    # copy outside, as colorize makes it.
    skin, shirt = np.full((40, 48, 1), 0.3), np.full((40, 48, 1), 0.8)
    source = identity_source((40, 48))
    source[..., 0] = 1
    mask = np.zeros((40, 48), bool)
    mask[:, 20:28] = True
    source[mask, 0] = 0
    reference = np.where(mask[..., None], 0.3, 0.8)
    tint = lambda out: float(np.abs(out[mask] - 0.3).max())  # noqa: E731
    # Treated as a seam between two palettes, the shirt's colour spreads into the neck.
    assert tint(seamless_copy([skin, shirt], source, reference, scale=6.0)) > 0.05
    assert tint(seamless_copy([skin, shirt], source, reference, scale=6.0, mask=mask)) < 1e-4
    with pytest.raises(ValueError, match="mask"):
        seamless_copy([skin, shirt], source, reference, mask=mask[:, :40])


def _sleeve_and_hand(exemplars=1, low=0.2, high=0.8):
    """A map copied from a textured exemplar whose left half is dark (a sleeve) and
    right half bright (a hand): the output's left half from the sleeve, its right half
    from inside the hand 8 px further on (or from a second exemplar), a seam at column 16
    between two sources; the voted reference shows the edge blurred."""
    rng = np.random.default_rng(3)
    texture = 0.03 * ndimage.gaussian_filter(rng.standard_normal((32, 48, 1)), (1, 1, 0))
    exemplar = np.where(np.arange(48)[None, :, None] < 20, low, high) + texture
    source = identity_source((32, 32))
    source[:, 16:, 2] += 8  # columns 24.. of the exemplar: inside the hand
    if exemplars == 2:
        source[:, 16:, 0] = 1
    step = np.where(np.arange(32) < 16, low, high).astype(float)
    reference = ndimage.gaussian_filter1d(step, 1.5)[None, :, None] * np.ones((32, 1, 1))
    return [exemplar, exemplar.copy()][:exemplars], source, reference


def test_an_edge_on_a_seam_within_one_exemplar_stays_sharp():
    exemplars, source, reference = _sleeve_and_hand()
    assert not coherent_edges(source)[0][:, 15].any()  # a seam, within one exemplar
    blended = seamless_copy(exemplars, source, reference, scale=6.0)
    kept = seamless_copy(exemplars, source, reference, scale=6.0, edge_support=0.3)
    jump = lambda out: float(np.mean(out[:, 16] - out[:, 15]))  # noqa: E731
    assert jump(blended) < 0.25  # spread over the blend scale
    assert jump(kept) > 0.5  # one pixel, nearly the full 0.6
    # Away from the seam the texture is the copy's either way.
    detail = np.diff(kept[:, 2:12, 0], axis=1).ravel()
    truth = np.diff(exemplars[0][:, 2:12, 0], axis=1).ravel()
    assert np.corrcoef(detail, truth)[0, 1] > 0.95


def test_a_faint_step_on_a_seam_is_shading_and_is_blended():
    # Two offsets of a smooth region differ by a little shading (0.03, under edge_floor):
    # next to smooth sides it passes the contrast test, but kept it draws a tile edge.
    exemplars, source, reference = _sleeve_and_hand(low=0.485, high=0.515)
    jump = lambda out: float(np.mean(out[:, 16] - out[:, 15]))  # noqa: E731
    assert jump(seamless_copy(exemplars, source, reference, scale=6.0, edge_support=0.3)) < 0.012
    # The contrast test alone keeps it.
    alone = seamless_copy(exemplars, source, reference, scale=6.0, edge_support=0.3, edge_floor=0)
    assert jump(alone) > 0.025


def test_the_blend_edge_defaults_are_the_depth_configurations():
    # core/ cannot import the depth front end's configuration: its defaults are repeated.
    parameters = inspect.signature(seamless_copy).parameters
    assert parameters["edge_contrast"].default == Finish().edge_contrast
    assert parameters["edge_floor"].default == Finish().edge_floor


def test_an_edge_the_reference_does_not_show_or_between_examples_is_blended():
    exemplars, source, reference = _sleeve_and_hand()
    flat = np.full_like(reference, 0.5)
    out = seamless_copy(exemplars, source, flat, scale=6.0, edge_support=0.3)
    assert float(np.mean(out[:, 16] - out[:, 15])) < 0.25
    two, source2, reference2 = _sleeve_and_hand(exemplars=2)
    out = seamless_copy(two, source2, reference2, scale=6.0, edge_support=0.3)
    assert float(np.mean(out[:, 16] - out[:, 15])) < 0.25  # a palette step: spread
    with pytest.raises(ValueError, match="edge_support"):
        seamless_copy(exemplars, source, reference, edge_support=2.0)


def test_pyramid_grows_with_large_objects():
    def square(side, canvas=1200):
        mask = np.zeros((canvas, canvas), bool)
        mask[:side, :side] = True
        return mask

    sizes = (7, 11, 9)
    assert pyramid_levels(square(80), sizes) == 3  # the paper's size: its 3 levels
    assert pyramid_levels(square(160), sizes) == 3
    assert pyramid_levels(square(300), sizes) == 4
    assert pyramid_levels(square(480), sizes) == 5  # coarsest 30 px: 3.3 windows across
    assert pyramid_levels(square(640), sizes) == 5
    # The preset's widths stay at the levels that see the object as at the paper's size;
    # the added finer levels repeat its finest width.
    assert level_patch_sizes(sizes, 5) == (7, 7, 7, 11, 9)
    assert level_patch_sizes(sizes, 2) == (7, 11)


def eye_object(shape=(64, 96), centre=(32, 48), radii=(20, 36), eye=(26, 26), palette=0):
    """A flat-ish ellipsoid with stripes and an eye (a dark ring) that has no depth signature."""
    h, w = shape
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    u = ((yy - centre[0]) / radii[0]) ** 2 + ((xx - centre[1]) / radii[1]) ** 2
    mask = u < 1
    # A flat slab: inside the silhouette nothing in the depth says where the eye is.
    depth = np.where(mask, 0.6, 0).astype(np.float32)
    colours = [((0.85, 0.6, 0.2), (0.35, 0.2, 0.1)), ((0.3, 0.7, 0.8), (0.1, 0.25, 0.4))][palette]
    x0 = centre[1] - radii[1]
    stripes = ((xx - x0) / (2 * radii[1]) * 6).astype(int) % 2 == 1
    image = np.where(stripes[..., None], colours[1], colours[0]).astype(np.float32)
    labels = np.where(mask, 1, 0)
    ring = np.hypot(yy - eye[0], xx - eye[1])
    eye_mask = mask & (ring < 3)
    image[eye_mask] = (0.95, 0.95, 0.9)
    image[mask & (ring < 1.5)] = (0.02, 0.02, 0.02)
    labels[eye_mask] = 2
    image[~mask] = 0
    return depth, image, labels


def test_an_eye_without_depth_signature_is_drawn_deterministically():
    """Two examples with an eye at the same relative place: the default map draws it."""
    d1, i1, l1 = eye_object(centre=(30, 46), radii=(19, 35), eye=(24, 26), palette=0)
    d2, i2, l2 = eye_object(centre=(33, 50), radii=(21, 37), eye=(27, 29), palette=1)
    db = Database(
        [Example.from_arrays("a", d1, i1, labels=l1), Example.from_arrays("b", d2, i2, labels=l2)]
    )
    depth, truth, labels = eye_object(centre=(32, 48), radii=(20, 36), eye=(26, 28))
    params = PRESETS["fish"].replace_fields(m=2)
    first = colorize(depth, db, params, seed=0)
    again = colorize(depth, db, params, seed=0)
    assert first.image.tobytes() == again.image.tobytes()
    assert features_drawn(first.image, truth, labels, depth > 0) == (1, 1)


@pytest.mark.parametrize("vote", ["mean", "mode"])
def test_target_never_increases_with_either_vote(blob_database, query_blob, vote):
    depth, _ = query_blob
    params = PRESETS["busts"].replace_fields(vote=vote)
    result = colorize(depth, blob_database, params, seed=3)
    for values in result.objective:
        assert np.all(np.diff(values) <= 1e-6 * np.abs(np.asarray(values[:-1])))


def test_copy_vote_is_crisper_than_the_mean_vote(blob_database, query_blob):
    depth, _ = query_blob
    voted = colorize(depth, blob_database, PRESETS["busts"].replace_fields(vote="mean"), seed=0)
    copied = colorize(depth, blob_database, PRESETS["busts"].replace_fields(vote="copy"), seed=0)
    images = [e.image for e in blob_database.examples]
    mask = depth > 0

    def ratio(result):
        names = [e.name for e in blob_database.examples]
        order = [images[names.index(n)] for n in result.example_names]
        return blur_ratio(result.image, copy_through(order, result.source), mask)

    assert ratio(copied) > ratio(voted)
    assert DepthConfig().finish.vote == "copy"


def test_a_missing_feature_at_the_silhouette_is_not_counted_as_drawn():
    """The object-to-background edge next to an eye must not pass for the eye."""
    mask = np.zeros((60, 80), bool)
    mask[10:50, 10:70] = True
    truth = np.repeat(np.where(mask, 0.7, 0.0)[..., None], 3, axis=2).astype(np.float32)
    labels = mask.astype(np.int32)
    truth[12:16, 12:16] = 0.05  # an eye two pixels from the edge
    labels[12:16, 12:16] = 2
    plain = np.repeat(np.where(mask, 0.6, 0.0)[..., None], 3, axis=2).astype(np.float32)
    assert features_drawn(truth, truth, labels, mask) == (1, 1)
    assert features_drawn(plain, truth, labels, mask) == (0, 1)


def domed_fish(shape=(64, 96), centre=(32, 48), radii=(20, 36), eye=(26, 26), palette=0):
    """A domed ellipsoid with stripes and a bulging eye (a dark ring on a small bump)."""
    h, w = shape
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    u = ((yy - centre[0]) / radii[0]) ** 2 + ((xx - centre[1]) / radii[1]) ** 2
    mask = u < 1
    ring = np.hypot(yy - eye[0], xx - eye[1])
    bump = 0.08 * np.sqrt(np.clip(1 - (ring / 3.5) ** 2, 0, 1))
    depth = np.where(mask, 0.3 + 0.3 * np.sqrt(np.clip(1 - u, 0, 1)) + bump, 0)
    colours = [((0.85, 0.6, 0.2), (0.35, 0.2, 0.1)), ((0.3, 0.7, 0.8), (0.1, 0.25, 0.4))][palette]
    stripes = ((xx - centre[1] + radii[1]) / (2 * radii[1]) * 6).astype(int) % 2 == 1
    image = np.where(stripes[..., None], colours[1], colours[0]).astype(np.float32)
    labels = np.where(mask, 1, 0)
    eye_mask = mask & (ring < 3)
    image[eye_mask] = (0.95, 0.95, 0.9)
    image[mask & (ring < 1.5)] = (0.02, 0.02, 0.02)
    labels[eye_mask] = 2
    image[~mask] = 0
    return depth.astype(np.float32), image, labels


#: The matching before registration (wave 2): positions relative to each object's
#: centroid, the example preference at the coarser levels only.
UNREGISTERED = dict(registration=False, example_preference=0.3, preference_at_finest=False)


def eye_at_the_outline():
    """Two domed fish whose eyes sit well inside their outlines, a query whose eye sits
    3 px from its own, and the share of that eye copied from the examples' eyes as a
    function of the fish preset's overrides (and of the final reseed's threshold, a
    constant of :mod:`imagemap.depth.guides`: 0 turns it off)."""
    d1, i1, l1 = domed_fish(centre=(30, 46), radii=(19, 35), eye=(24, 24), palette=0)
    d2, i2, l2 = domed_fish(centre=(33, 50), radii=(21, 37), eye=(27, 28), palette=1)
    db = Database(
        [Example.from_arrays("a", d1, i1, labels=l1), Example.from_arrays("b", d2, i2, labels=l2)]
    )
    depth, _, labels = domed_fish(centre=(32, 48), radii=(16, 36), eye=(24, 24))
    mask, eye = depth > 0, labels == 2
    assert ndimage.distance_transform_edt(mask)[eye].min() <= 2  # the eye touches the edge

    def eye_copied_from_eyes(final_reseed=FINAL_RESEED, **overrides):
        with pytest.MonkeyPatch.context() as patch:
            patch.setattr("imagemap.depth.guides.FINAL_RESEED", final_reseed)
            config = PRESETS["fish"].replace_fields(m=2, **overrides)
            result = colorize(depth, db, config, seed=0)
        by_name = {"a": l1, "b": l2}
        example_labels = [by_name[name] for name in result.example_names]
        return np.mean(source_labels(result.source, example_labels, mask)[eye] == 2)

    return eye_copied_from_eyes


def test_an_eye_next_to_the_outline_is_copied_from_the_examples_eyes():
    """The query's eye sits 3 px from its outline, the examples' well inside theirs.

    With the paper's bands (depth and Laplacian colour bands) the outline's jump to
    background outweighs the eye's bulge and the eye is copied from plain body; the
    silhouette band (depth continued past the outline) and the guide reseed copy it
    from the eyes, and so, on the paper's bands otherwise, do plain colour levels.
    """
    eye_copied_from_eyes = eye_at_the_outline()
    # The synthesis runs at the examples' scale (the query is 1.07x smaller than the
    # first): brought back, the 5 x 5 eye is one row off, 0.8 of it from the eyes.
    assert eye_copied_from_eyes() >= 0.75
    assert eye_copied_from_eyes(appearance_pyramid="laplacian") >= 0.75
    # The paper's matching too (relative position, the preference at the coarse levels
    # only): a registered warp places the eye by itself. Measured 0.64.
    papers = dict(silhouette_weight=0.0, guide_reseed=0.0, final_reseed=0.0, **UNREGISTERED)
    lost = eye_copied_from_eyes(appearance_pyramid="laplacian", **papers)
    assert lost <= eye_copied_from_eyes() - 0.1
    # Plain colours: the eye's window carries its full colour at every level, so the
    # coarser levels' dark dot is matched by the examples' eyes, not by plain body.
    assert eye_copied_from_eyes(**papers) >= lost + 0.1


def test_the_final_reseed_brings_back_an_eye_the_em_lost():
    """Without the silhouette band and the per-level reseed the EM copies the
    query's eye (3 px from its outline) from plain body; the final reseed, where
    the finest matches fit the relief worst, takes it from the examples' eyes."""
    eye_copied_from_eyes = eye_at_the_outline()
    lost = dict(
        silhouette_weight=0.0,
        guide_reseed=0.0,
        appearance_pyramid="laplacian",
        **UNREGISTERED,  # a registered warp places the eye by itself
    )
    without = eye_copied_from_eyes(final_reseed=0.0, **lost)
    assert without <= 0.7  # measured 0.64 (the eye's rim from body)
    assert eye_copied_from_eyes(**lost) >= without + 0.1


def test_the_mean_vote_is_the_ems_own_map_whatever_the_final_reseed(
    blob_database, query_blob, monkeypatch
):
    """The final reseed changes the matches the copy is made from, after the EM: the
    paper's mean vote (and its source map) and the EM's target trace stay the same."""
    depth, _ = query_blob

    def run(vote, final_reseed):
        monkeypatch.setattr("imagemap.depth.guides.FINAL_RESEED", final_reseed)
        return colorize(depth, blob_database, PRESETS["busts"].replace_fields(vote=vote), seed=0)

    results = [run(vote, r) for vote in ("mean", "copy") for r in (0.0, FINAL_RESEED)]
    mean_off, mean_on, copy_off, copy_on = results
    assert np.array_equal(mean_off.image, mean_on.image)
    assert np.array_equal(mean_off.source, mean_on.source)
    assert copy_off.objective == copy_on.objective
    assert mean_off.objective == copy_on.objective


def test_silhouette_band_is_a_clipped_signed_distance():
    from imagemap.depth.config import Guides
    from imagemap.depth.guides import silhouette_band as _silhouette_band

    SILHOUETTE_RANGE = Guides().silhouette_range

    mask = np.zeros((20, 20), bool)
    mask[5:15, 5:15] = True
    band = _silhouette_band(mask)
    assert band[10, 10] == 1.0 and band[0, 0] == -1.0  # saturated far inside and outside
    assert band[5, 10] == pytest.approx(1 / SILHOUETTE_RANGE)  # first row inside
    assert band[4, 10] == pytest.approx(-1 / SILHOUETTE_RANGE)  # first row outside


def test_guide_reseed_must_be_a_fraction():
    from imagemap.core.engine import uniform_levels

    with pytest.raises(ValueError, match="guide_reseed"):
        uniform_levels((7,), guide_reseed=1.5)
    with pytest.raises(ValueError, match="final_reseed"):
        uniform_levels((7,), final_reseed=1.0)


@pytest.mark.parametrize(
    "field, value",
    [
        ("silhouette_weight", -0.5),
        ("silhouette_weight", float("nan")),
        ("guide_reseed", 1.0),
        ("wide_context_weight", -0.25),
        ("edge_support", 1.5),
        ("edge_support", float("nan")),
        ("appearance_pyramid", "lap"),
        ("appearance_pyramid", "Gaussian"),
    ],
)
def test_new_colorize_settings_are_checked(field, value):
    from imagemap.io import InputError

    with pytest.raises(InputError, match=field):
        DepthConfig().replace_fields(**{field: value})


def test_context_is_the_coarser_levels_colours_on_the_finer_grid():
    """For Laplacian bands the running collapse gives each level's Gaussian level
    (known answer, up to rounding), and brought to the finer grid it is what the
    coarser levels sum to there: the finer Gaussian level minus its own band."""
    from imagemap.core.engine import Mapping, _coarse_colours, _context
    from imagemap.core.pyramid import gaussian_pyramid, laplacian_pyramid

    image = np.random.default_rng(0).random((37, 50, 3)).astype(np.float32)
    bands, gaussians = laplacian_pyramid(image, 4), gaussian_pyramid(image, 4)
    colours = None
    for level in range(3, 0, -1):
        colours = _coarse_colours(colours, bands[level], "laplacian")
        np.testing.assert_allclose(colours, gaussians[level], atol=1e-5)
        finer = Mapping(guide=np.zeros(bands[level - 1].shape[:2]), appearance=bands[level - 1])
        context = _context(finer, colours)
        np.testing.assert_allclose(context, gaussians[level - 1] - bands[level - 1], atol=1e-5)
    assert _coarse_colours(colours, gaussians[0], "gaussian") is not colours


def test_only_fine_levels_of_large_objects_get_context():
    from imagemap.depth.guides import context_level_weights, context_levels, level_plans

    small = np.zeros((150, 200), bool)
    small[40:110, 60:140] = True  # a 75 px object, the paper's scale
    assert context_levels(small, (7, 11, 9)) == 0
    weak = DepthConfig().replace_fields(wide_context_weight=0.0)
    assert all(not plan.has_context for plan in level_plans(weak, small, 2))
    big = np.kron(small, np.ones((4, 4), bool))
    assert context_levels(big, (7, 11, 9, 9)) == 1
    plans = level_plans(weak.replace_fields(patch_sizes=(7, 11, 9, 9)), big, 2)
    assert [plan.has_context for plan in plans] == [True, False, False, False]
    assert len(plans[0].context_weights) == 3
    # Every level but the coarsest gets the weak context; the fine ones the full one.

    assert context_level_weights(small, (7, 11, 9), 0.25) == (2, (0.25, 0.25, 0.0))
    assert context_level_weights(big, (7, 11, 9, 9), 0.25) == (3, (1.0, 0.25, 0.25, 0.0))
    assert context_level_weights(big, (7, 11, 9, 9)) == (1, (1.0, 0.0, 0.0, 0.0))


def _busts_mappings(blob_database, query_blob, levels=3):
    """The query's and the first two examples' mappings with the busts preset's bands."""
    from imagemap.depth.guides import depth_mappings, example_mappings

    guides = PRESETS["busts"].guides
    query = depth_mappings(query_blob[0], levels, guides)
    examples = blob_database.examples[:2]
    return query, [example_mappings(e, levels, "laplacian", guides) for e in examples]


def _busts_engine_params(levels_with_context, weight=1.0, max_iterations=3):
    """The busts preset's engine parameters for three levels, with the luma context at
    ``levels_with_context`` (level -> factor) only."""
    from imagemap.core.params import LevelPlan
    from imagemap.depth.pipeline import engine_params

    mask = np.ones((48, 64), bool)
    params = engine_params(PRESETS["busts"], mask, 2)
    plans = tuple(
        LevelPlan(
            patch_size=plan.patch_size,
            max_iterations=max_iterations,
            exemplar_costs=plan.exemplar_costs,
            context_weights=(
                (weight * levels_with_context[level], 0.0, 0.0)
                if level in levels_with_context
                else ()
            ),
            guide_reseed=plan.guide_reseed,
            final_reseed=plan.final_reseed,
        )
        for level, plan in enumerate(params.levels)
    )
    return replace(params, levels=plans)


def test_a_level_weight_of_zero_is_no_context_there(blob_database, query_blob):
    from imagemap.core.engine import synthesize

    query, exemplars = _busts_mappings(blob_database, query_blob)
    finest = _busts_engine_params({0: 1.0})
    weighted = _busts_engine_params({0: 1.0, 1: 0.0})
    a = synthesize(query, exemplars, finest, seed=1)
    b = synthesize(query, exemplars, weighted, seed=1)
    assert a.appearance[0].tobytes() == b.appearance[0].tobytes()
    weak = _busts_engine_params({0: 0.25})
    c = synthesize(query, exemplars, weak, seed=1)
    assert c.appearance[0].tobytes() != a.appearance[0].tobytes()


def test_context_keeps_the_target_monotone_and_the_bytes(blob_database, query_blob):
    """With context on every fine level the EM still never raises its target, and the
    same seed gives the same bytes; without it the map differs (it is used)."""
    from imagemap.core.engine import synthesize
    from imagemap.core.params import LevelPlan

    query, exemplars = _busts_mappings(blob_database, query_blob)
    on = _busts_engine_params({0: 1.0, 1: 1.0}, max_iterations=4)
    off = _busts_engine_params({}, max_iterations=4)
    first, again = (
        synthesize(query, exemplars, on, seed=1),
        synthesize(query, exemplars, on, seed=1),
    )
    assert first.appearance[0].tobytes() == again.appearance[0].tobytes()
    for values in first.objective:
        assert np.all(np.diff(values) <= 1e-6 * np.abs(np.asarray(values[:-1])))
    plain = synthesize(query, exemplars, off, seed=1)
    assert plain.appearance[0].tobytes() != first.appearance[0].tobytes()
    wrong = (LevelPlan(patch_size=7, context_weights=(1.0,)),) + on.levels[1:]
    with pytest.raises(ValueError, match="context weights"):
        synthesize(query, exemplars, replace(on, levels=wrong), seed=1)


def test_the_blend_keeps_the_rim_at_the_copys_colours(blob_database, query_blob):
    """Outside the object the voted map holds whatever the windows left there (zeros
    on plain colour levels: green in YCbCr); the blend's reference there is the copy,
    so the rim keeps the copied colours (it had drifted 0.16 towards the zeros)."""
    from imagemap.depth.guides import example_ycbcr as _example_ycbcr
    from imagemap.depth.guides import to_ycbcr

    depth, _ = query_blob
    # Centroid positions: the registered copy needs almost no blending inside, which
    # leaves the comparison with the interior nothing to measure.
    result = colorize(depth, blob_database, PRESETS["busts"].replace_fields(**UNREGISTERED), seed=0)
    assert result.config.matching.appearance_pyramid == "gaussian"
    mask = depth > 0
    rim = mask & ~ndimage.binary_erosion(mask, iterations=3)
    copied = copy_through(
        [_example_ycbcr(blob_database[name]) for name in result.example_names], result.source
    )
    gap = np.abs(to_ycbcr(result.image) - copied)
    assert gap[rim].mean() < 0.02
    assert gap[rim].mean() <= 2 * gap[mask & ~rim].mean()  # no worse than the interior


def test_example_mappings_refuse_the_old_boolean(blob_database):
    """``example_mappings`` took ``use_pyramid=True`` where it now takes a pyramid name:
    a leftover bool is refused rather than read silently as plain colours."""
    from imagemap.depth.guides import example_mappings

    example = blob_database.examples[0]
    with pytest.raises(ValueError, match="appearance_pyramid"):
        example_mappings(example, 2, True)
    plain, bands = (example_mappings(example, 2, kind) for kind in ("gaussian", "laplacian"))
    assert np.allclose(plain[1].appearance, bands[1].appearance)  # the coarsest level: equal
    assert not np.allclose(plain[0].appearance, bands[0].appearance)


@pytest.mark.parametrize("saturation", [1.0, 1.5, 2.0, 3.7, 6.0])
def test_silhouette_band_equals_the_distance_transforms(saturation):
    # Below the switch the band is found from the offsets nearer than the saturation,
    # above it from two distance transforms: both must be the signed distance, clipped.
    rng = np.random.default_rng(7)
    for trial in range(9):
        mask = ndimage.gaussian_filter(rng.random((37 + trial, 45)), 2.5) > 0.5
        if trial >= 5:  # an object in a part of a larger frame (the band on its box)
            mask = np.pad(mask[: 10 + trial, 5:30], [(trial - 4, 13), (40 - trial, 2 * trial)])
        inside = ndimage.distance_transform_edt(mask)
        outside = ndimage.distance_transform_edt(~mask)
        expected = np.clip((inside - outside) / saturation, -1, 1).astype(np.float32)
        np.testing.assert_array_equal(silhouette_band(mask, saturation), expected)


@pytest.mark.parametrize("piece", [None, 5])
def test_the_blends_shifted_copies_are_copy_through_clipped(monkeypatch, piece):
    """_copy_channel reads each source from its exemplar's flat values: the values of
    copy_through shifted by (dy, dx) and clipped to the exemplar, the reference where
    a pixel has no source; exemplars of different sizes, and a grey one; whole groups or
    a few pixels at a time."""
    from imagemap.core import poisson

    if piece is not None:
        monkeypatch.setattr(poisson, "_PIECE", piece)
    rng = np.random.default_rng(9)
    exemplars = [rng.random((13, 17, 3)).astype(np.float32), rng.random((9, 6, 3))]
    source = random_source(rng, (11, 14), (9, 6))
    source[0, :5, 1:] = [12, 20]  # past the smaller exemplar: clipped, as copy_through
    has = source[..., 0] >= 0
    reference = rng.random((11, 14))
    groups = poisson._source_groups(exemplars, source)
    for dy, dx in [(0, 0), (0, 1), (0, -1), (1, 0), (-1, 0)]:
        for channel in range(3):
            expected = copy_through([e[..., channel] for e in exemplars], source, dy, dx)
            found = poisson._copy_channel(groups, reference, channel, dy, dx)
            assert found.dtype == np.float64
            assert np.array_equal(found, np.where(has, expected, reference))
            # A float32 channel of a map (a strided view) is read as float64, unchanged.
            single = np.stack([reference] * 3, axis=-1).astype(np.float32)[..., channel]
            found = poisson._copy_channel(groups, single, channel, dy, dx)
            assert found.dtype == np.float64 and found.flags.c_contiguous
            assert np.array_equal(found, np.where(has, expected, single.astype(np.float64)))
    grey = poisson._source_groups([exemplars[0][..., 0]], np.maximum(source, 0) * [0, 1, 1])
    found = poisson._copy_channel(grey, reference, 0, 1, 0)
    assert np.array_equal(
        found, copy_through([exemplars[0][..., 0]], np.maximum(source, 0) * [0, 1, 1], 1, 0)
    )


def test_the_blend_written_over_its_reference_is_the_same_map():
    """seamless_copy(out=reference) reads each channel of the reference before writing
    it: the same bytes as a fresh result, edges kept and an object's outline too."""
    rng = np.random.default_rng(5)
    exemplars = [rng.random((40, 50, 3)).astype(np.float32), rng.random((30, 44, 3))]
    source = random_source(rng, (36, 41), (30, 44))
    source[8:20, 5:30, 0] = 0  # a coherent block: copied gradients to keep
    source[8:20, 5:30, 1:] = np.stack(np.mgrid[3:15, 10:35], axis=-1)
    mask = np.zeros((36, 41), bool)
    mask[4:30, 3:38] = True
    reference = rng.random((36, 41, 3)).astype(np.float32)
    options = dict(scale=5.0, edge_support=0.3, mask=mask)
    expected = seamless_copy(exemplars, source, reference, **options)
    given = reference.copy()
    found = seamless_copy(exemplars, source, given, out=given, **options)
    assert found is given and not np.array_equal(found, reference)
    assert np.array_equal(found, expected)
    with pytest.raises(ValueError, match="out"):
        seamless_copy(exemplars, source, reference, out=reference.astype(np.float64))


def test_colour_conversions_are_skimages_without_importing_it():
    """to_ycbcr and to_rgb hold skimage.color's matrices and give its values (float32 and
    float64 pictures, past [0, 1] too); an integer picture is left to skimage (it rescales
    it). skimage inverts its matrix at import with the machine's LAPACK, whose last bits
    differ by CPU (AMD EPYC's OpenBLAS kernels: two near-zero entries, ~1e-9, 5e-20 apart
    from the Intel machines' inverse held here): equal to within that rounding."""
    from skimage import color
    from skimage.color import colorconv

    from imagemap.depth import guides

    assert np.array_equal(guides._YCBCR_FROM_RGB, colorconv.ycbcr_from_rgb)
    np.testing.assert_allclose(
        guides._RGB_FROM_YCBCR, colorconv.rgb_from_ycbcr, rtol=1e-15, atol=1e-18
    )
    rng = np.random.default_rng(10)
    for dtype in (np.float32, np.float64):
        rgb = (rng.random((guides._ROWS + 3, 9, 3)) * 1.2 - 0.1).astype(dtype)
        ycbcr = guides.to_ycbcr(rgb)
        expected = np.concatenate(
            [color.rgb2ycbcr(rgb[:256]) / 255.0, color.rgb2ycbcr(rgb[256:]) / 255.0]
        ).astype(np.float32)
        assert np.array_equal(ycbcr, expected)
        back = np.clip(color.ycbcr2rgb(ycbcr.astype(np.float64) * 255.0), 0.0, 1.0)
        assert np.array_equal(guides.to_rgb(ycbcr), back.astype(np.float32))
    grey = rng.integers(0, 256, (4, 5, 3)).astype(np.uint8)
    assert np.array_equal(guides.to_ycbcr(grey), (color.rgb2ycbcr(grey) / 255.0).astype(np.float32))


def test_example_colours_are_the_copy_stages_colours():
    """The colours the bands make (and keep for the copy stage on small frames) are the
    bytes of example_ycbcr's, with the nearest object pixels it filled from."""
    from imagemap.core.blend import nearest_object_pixels
    from imagemap.depth.guides import example_colours, example_ycbcr

    yy, xx = np.mgrid[0:60, 0:80]
    depth = np.where((yy - 30) ** 2 / 400 + (xx - 40) ** 2 / 900 < 1, 1.0, 0.0)
    image = np.random.default_rng(14).random((60, 80, 3)) * (depth > 0)[..., None]
    example = Example.from_arrays("e", depth.astype(np.float32), image)
    colours, nearest = example_colours(example)
    assert np.array_equal(colours, example_ycbcr(example))
    assert nearest is not None and np.array_equal(nearest, nearest_object_pixels(depth > 0))
