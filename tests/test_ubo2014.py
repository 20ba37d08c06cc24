"""The Bonn UBO2014 (DFMF) reader and writer: layouts, ambiguous sizes, validation."""

from __future__ import annotations

import struct

import numpy as np
import pytest

from imagemap.btf.ubo2014 import read_ubo2014, write_ubo2014
from imagemap.io import InputError

# 8 lights x 2 views = 16 direction pairs = 4 x 4 texels: the layouts have equal sizes.
LIGHTS = np.stack([np.full(8, 30.0), np.arange(8) * 45.0], axis=1).astype(np.float32)
VIEWS = np.array([[0, 0], [45, 90]], np.float32)


def _factors(rng, height, width, ks=(4, 3, 2)):
    n_pairs = len(VIEWS) * len(LIGHTS)
    us = [np.linalg.qr(rng.normal(size=(n_pairs, k)))[0] for k in ks]
    sigmas = [np.sort(rng.random(k))[::-1] + 1 for k in ks]
    sxvs = [rng.normal(size=(height, width, k)) for k in ks]
    return us, sigmas, sxvs


def _truth(us, sxvs, light: int, view: int) -> np.ndarray:
    file_row = view * len(LIGHTS) + light  # the file's rows: view-major, light fastest
    return np.stack([sxv @ u[file_row] for u, sxv in zip(us, sxvs, strict=True)], axis=2)


def _write(path, us, sigmas, sxvs, **kwargs):
    return write_ubo2014(
        path,
        eigen_abrdfs=us,
        singular_values=sigmas,
        eigentextures=sxvs,
        light_dirs=LIGHTS,
        view_dirs=VIEWS,
        **kwargs,
    )


@pytest.mark.parametrize(
    "size, layout",
    [
        ((4, 4), "abrdfs"),  # texels == pairs: the old reader took this as transposed
        ((5, 7), "abrdfs"),
        ((5, 7), "images"),  # the transposed layout, told apart by the file's sizes
    ],
)
def test_layouts_read_back_to_float_precision(tmp_path, size, layout):
    rng = np.random.default_rng(3)
    us, sigmas, sxvs = _factors(rng, *size)
    path = _write(tmp_path / "t.btf", us, sigmas, sxvs, layout=layout)
    btf = read_ubo2014(path)
    assert btf.shape == size and btf.n_components == 9
    worst = 0.0
    for light, view in [(0, 0), (5, 1), (7, 0)]:
        want = _truth(us, sxvs, light, view)
        got = btf.image(light, view, rgb=False)
        worst = max(worst, float(np.abs(got - want).max() / np.abs(want).max()))
    assert worst < 1e-5, worst


@pytest.mark.parametrize("scalar_size, tolerance", [(2, 2e-3), (8, 1e-6)])
def test_half_and_double_scalars(tmp_path, scalar_size, tolerance):
    rng = np.random.default_rng(4)
    us, sigmas, sxvs = _factors(rng, 4, 4)
    btf = read_ubo2014(_write(tmp_path / "t.btf", us, sigmas, sxvs, scalar_size=scalar_size))
    want = _truth(us, sxvs, 3, 1)
    error = np.abs(btf.image(3, 1, rgb=False) - want).max() / np.abs(want).max()
    assert error < tolerance


def test_total_components_field_is_the_largest_k_as_btflib_writes_it(tmp_path):
    rng = np.random.default_rng(5)
    us, sigmas, sxvs = _factors(rng, 4, 4, ks=(5, 3, 2))
    data = _write(tmp_path / "t.btf", us, sigmas, sxvs).read_bytes()
    pos = 10 + struct.unpack_from("<I", data, 10)[0]  # signature, meta block
    pos += 4 + len(VIEWS) * (8 + 4 + 8 * len(LIGHTS))  # views and their lights
    pos += 8 + 4  # width, height, no rotations
    assert struct.unpack_from("<I", data, pos)[0] == 5


@pytest.mark.parametrize(
    "change, message",
    [
        (lambda us, ss, ws: (us[:2] + [np.zeros((67, 2))], ss, ws), r"eigen_abrdfs\[2\].*16, 2"),
        (lambda us, ss, ws: (us, ss[:1] + [np.ones(4)] + ss[2:], ws), r"eigen_abrdfs\[1\]"),
        (lambda us, ss, ws: (us, ss, ws[:2] + [np.zeros((4, 5, 2))]), r"eigentextures\[2\]"),
        (lambda us, ss, ws: (us, ss, ws[:2] + [np.zeros((4, 4, 3))]), r"eigentextures\[2\]"),
        (lambda us, ss, ws: (us, ss[:2], ws), "one factor per channel"),
        (lambda us, ss, ws: (us, ss, ws[:1] + [ws[1] * np.nan] + ws[2:]), "NaN"),
    ],
)
def test_writer_refuses_inconsistent_shapes_before_writing(tmp_path, change, message):
    rng = np.random.default_rng(6)
    us, sigmas, sxvs = change(*_factors(rng, 4, 4))
    path = tmp_path / "t.btf"
    with pytest.raises(InputError, match=message):
        _write(path, us, sigmas, sxvs)
    assert not path.exists() and list(tmp_path.iterdir()) == []


def test_writer_refuses_bad_options(tmp_path):
    us, sigmas, sxvs = _factors(np.random.default_rng(7), 4, 4)
    for kwargs, message in [
        ({"scalar_size": 3}, "scalar_size"),
        ({"layout": "rows"}, "layout"),
        ({"color_mean": (0, 0)}, "color_mean"),
        ({"color_model": "LAB"}, "color_model"),
    ]:
        with pytest.raises(InputError, match=message):
            _write(tmp_path / "t.btf", us, sigmas, sxvs, **kwargs)
    assert list(tmp_path.iterdir()) == []
