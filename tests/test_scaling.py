"""What the speed and memory work must keep: selection by the examples' precomputed shape
grids does not depend on the query's pose, and the copy finish's channel-by-channel solve
gives the all-channels result."""

from __future__ import annotations

import numpy as np
from scipy import fft, ndimage

from imagemap import Database, Example, select_examples
from imagemap.core.blend import copy_through
from imagemap.core.poisson import seamless_copy


def _creature(shape, centre, length, aspect, angle=0.0, mirrored=False, scale=1.0):
    """An ellipsoid with a bump at one end (its head): turned, mirrored, scaled, placed."""
    yy, xx = np.mgrid[0 : shape[0], 0 : shape[1]].astype(np.float64)
    dy, dx = (yy - centre[0]) / scale, (xx - centre[1]) / scale
    theta = np.deg2rad(angle)
    u = np.cos(theta) * dx - np.sin(theta) * dy  # along the body (y down, turned on screen)
    v = np.sin(theta) * dx + np.cos(theta) * dy
    u = -u if mirrored else u
    a, b = length / 2, length / 2 / aspect
    r2 = (u / a) ** 2 + (v / b) ** 2
    body = 0.3 + 0.6 * np.sqrt(np.clip(1 - r2, 0, 1))
    head = 0.25 * np.exp(-((u - 0.6 * a) ** 2 + (v + 0.3 * b) ** 2) / (0.08 * a * a))
    return np.where(r2 < 1, body + head, 0).astype(np.float32)


def test_selection_does_not_depend_on_pose_size_place_or_units():
    """#42: the examples chosen and their order are the same for a query turned, mirrored,
    scaled, moved or in other depth units; the pose found says how it lies."""
    examples = [
        Example.from_arrays(
            f"a{aspect:.2f}",
            _creature((70, 90), (35, 45), 60, aspect),
            np.zeros((70, 90, 3)),
        )
        for aspect in (1.2, 1.5, 1.8, 2.1, 2.4, 2.7, 3.0)
    ]
    database = Database(examples)
    upright = select_examples(_creature((80, 100), (40, 50), 56, 2.0), database, m=3)
    assert [database[i].name for i in upright[:2]] == ["a2.10", "a1.80"]
    from imagemap.depth.selection import select_with_poses

    for angle, mirrored, scale, centre, units in (
        (30.0, False, 1.0, (40, 50), 1.0),
        (-40.0, False, 1.0, (40, 50), 1.0),
        (0.0, True, 1.0, (40, 50), 1.0),
        (20.0, True, 0.7, (30, 62), 1.0),
        (0.0, False, 1.5, (40, 50), 1e3),
    ):
        query = units * _creature((80, 100), centre, 56, 2.0, angle, mirrored, scale)
        chosen, poses = select_with_poses(query, database, m=3)
        assert chosen == upright, (angle, mirrored, scale)
        first = poses[0]
        assert first.mirrored == mirrored
        turn = -angle if not mirrored else angle  # the pose turns the query back
        assert abs(first.angle - turn) < 3.0, (first.angle, angle, mirrored)
        assert abs(first.scale * scale - 60 / 56) < 0.08


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
