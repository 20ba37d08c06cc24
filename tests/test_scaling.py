"""What the speed and memory work must keep: selection by the precomputed statistics ranks
examples as the direct centroid-aligned SSD does, and the copy finish's channel-by-channel
solve gives the all-channels result."""

from __future__ import annotations

import numpy as np
from scipy import fft, ndimage

from imagemap import Database, Example, select_examples
from imagemap.align import centroid_shift, translate
from imagemap.core.blend import copy_through
from imagemap.core.poisson import seamless_copy


def _direct_ranking(depth, database):
    """The definition: SSD of the query and each translated example, plus the example's
    depth that falls outside the query frame."""
    distances = []
    for example in database:
        other = example.depth.astype(np.float64)
        shifted = translate(other, centroid_shift(other > 0, depth > 0), depth.shape)
        outside = np.square(other).sum() - np.square(shifted.astype(np.float64)).sum()
        distances.append(np.square(depth - shifted.astype(np.float64)).sum() + outside)
    return list(np.argsort(distances, kind="stable")), distances


def _blob(rng, shape, centre, radii):
    yy, xx = np.mgrid[0 : shape[0], 0 : shape[1]]
    r2 = ((yy - centre[0]) / radii[0]) ** 2 + ((xx - centre[1]) / radii[1]) ** 2
    bumps = 0.05 * rng.random(shape)
    return np.where(r2 < 1, 0.3 + 0.6 * np.sqrt(np.clip(1 - r2, 0, 1)) + bumps, 0).astype(
        np.float32
    )


def test_selection_ranks_as_the_direct_ssd():
    rng = np.random.default_rng(4)
    examples = []
    for i in range(25):
        shape = (int(rng.integers(30, 70)), int(rng.integers(30, 90)))  # sizes differ
        centre = (rng.uniform(0.2, 0.8) * shape[0], rng.uniform(0.2, 0.8) * shape[1])
        radii = (rng.uniform(5, shape[0] / 2), rng.uniform(5, shape[1] / 2))
        depth = _blob(rng, shape, centre, radii)
        examples.append(Example.from_arrays(f"e{i:02d}", depth, np.zeros(shape + (3,))))
    database = Database(examples)
    for q in range(5):
        query = _blob(rng, (50, 60), (25 + 3 * q, 30 - 2 * q), (12 + q, 20 - q))
        order, distances = _direct_ranking(query, database)
        chosen = select_examples(query, database, m=5)
        # Same ranking (up to exact ties, which the fixtures do not have).
        assert chosen == [int(i) for i in order[:5]], (chosen, order[:5])
        assert len(set(np.round(distances, 6))) == len(distances)


def _all_channels_reference(exemplars, source, reference, scale):
    """The copy finish written over all channels at once (the former implementation)."""
    reference = np.asarray(reference, dtype=np.float64)
    h, w, _ = reference.shape
    has = (source[..., 0] >= 0)[..., None]

    def shifted(dy, dx):
        return np.where(has, copy_through(exemplars, source, dy, dx), reference)

    copy, right, left = shifted(0, 0), shifted(0, 1), shifted(0, -1)
    down, up = shifted(1, 0), shifted(-1, 0)

    def stronger(a, b):
        return np.where((np.square(a).sum(-1) >= np.square(b).sum(-1))[..., None], a, b)

    gx = stronger(right[:, :-1] - copy[:, :-1], copy[:, 1:] - left[:, 1:])
    gy = stronger(down[:-1] - copy[:-1], copy[1:] - up[1:])
    none_x = ~(has[:, 1:] & has[:, :-1])[..., 0]
    none_y = ~(has[1:] & has[:-1])[..., 0]
    gx[none_x] = (reference[:, 1:] - reference[:, :-1])[none_x]
    gy[none_y] = (reference[1:] - reference[:-1])[none_y]
    lam = 1.0 / scale**2
    rhs = lam * reference
    rhs[:, 1:] += gx
    rhs[:, :-1] -= gx
    rhs[1:] += gy
    rhs[:-1] -= gy
    eig_y = 2.0 - 2.0 * np.cos(np.pi * np.arange(h) / h)
    eig_x = 2.0 - 2.0 * np.cos(np.pi * np.arange(w) / w)
    denominator = (lam + eig_y[:, None] + eig_x[None, :])[..., None]
    spectrum = fft.dctn(rhs, type=2, axes=(0, 1), norm="ortho")
    return fft.idctn(spectrum / denominator, type=2, axes=(0, 1), norm="ortho").astype(np.float32)


def test_seamless_copy_by_channel_equals_all_channels_at_once():
    rng = np.random.default_rng(1)
    h, w = 61, 83
    exemplars = [
        ndimage.gaussian_filter(rng.random((70, 90, 3)), (2, 2, 0)).astype(np.float32),
        rng.random((40, 100, 3)).astype(np.float32),
    ]
    yy, xx = np.mgrid[0:h, 0:w]
    source = np.stack([rng.integers(-1, 2, (h, w)), yy, xx], axis=-1).astype(np.int32)
    source[: h // 2, : w // 2, 0] = 0  # a coherent region, seams around it
    source[h // 2 :, :, 1] += 3
    reference = rng.random((h, w, 3)).astype(np.float32)
    expected = _all_channels_reference(exemplars, source, reference, 6.0)
    result = seamless_copy(exemplars, source, reference, scale=6.0)
    assert result.dtype == np.float32
    assert np.array_equal(result, expected)


def test_colour_conversion_in_row_blocks_equals_whole_image():
    from skimage import color

    from imagemap.depth.guides import _ROWS, to_ycbcr

    rgb = np.random.default_rng(2).random((2 * _ROWS + 17, 9, 3)).astype(np.float32)
    whole = (color.rgb2ycbcr(rgb) / 255.0).astype(np.float32)
    assert np.array_equal(to_ycbcr(rgb), whole)


def test_kernels_work_in_a_forked_child():
    """A forked child inherits the kernels' thread pools without their threads."""
    import multiprocessing

    from imagemap.core import kernels as _kernels

    out = np.zeros((40, 40, 1), np.float32)
    lookup = np.zeros((38, 38), np.int32)
    args = (np.ones((1, 40, 40, 1), np.float32), np.ones((3, 3), np.float32), lookup,
            np.zeros(1, np.int32), np.zeros(1, np.int32), np.zeros(1, np.int32),
            np.zeros(1, np.int64))  # fmt: skip
    _kernels.vote(*args, out)  # the pool exists in this process now
    context = multiprocessing.get_context("fork")
    with context.Pool(1) as pool:
        result = pool.apply_async(_vote_in_child, args).get(timeout=120)
    assert result == float(out.sum())


def _vote_in_child(*args):
    from imagemap.core import kernels as _kernels

    out = np.zeros((40, 40, 1), np.float32)
    _kernels.vote(*args, out)
    return float(out.sum())
