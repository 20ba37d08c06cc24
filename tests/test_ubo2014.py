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


# -- an independent reader, written from the format description in the module docstring ------


def _independent_read(path) -> dict:
    """Decode a DFMF file from the docstring's description alone (not from our reader)."""
    data = path.read_bytes()
    pos = 0

    def take(fmt):
        nonlocal pos
        values = struct.unpack_from("<" + fmt, data, pos)
        pos += struct.calcsize("<" + fmt)
        return values

    def floats(dtype, count):
        nonlocal pos
        array = np.frombuffer(
            data, dtype=np.dtype(dtype).newbyteorder("<"), count=count, offset=pos
        )
        pos += array.nbytes
        return array.astype(np.float64)

    assert data[:10] == b"!DFMF08FCR"
    pos = 10
    meta_size, version = take("II")
    assert version == 4
    pos += 240 + 16 + 4  # three descriptions, ppmm + rgb scale, cosine flag
    (xml_length,) = take("I")
    pos += xml_length
    (n_channels,) = take("I")
    names = []
    for _ in range(n_channels):
        (length,) = take("I")
        names.append(data[pos : pos + length].decode("ascii"))
        pos += length
    assert pos == 10 + meta_size
    (n_views,) = take("I")
    views, lights = [], []
    for _ in range(n_views):
        views.append(take("ff"))
        (n_lights,) = take("I")
        lights.append(floats(np.float32, 2 * n_lights).reshape(n_lights, 2))
    width, height = take("II")
    (n_rotations,) = take("I")
    pos += 36 * n_rotations
    _, model = take("Ii")
    pos += 12 + 36  # colour mean, colour transformation
    channels = []
    for _ in range(n_channels):
        scalar, k, rows, cols = take("BIII")
        dtype = {2: np.float16, 4: np.float32, 8: np.float64}[scalar]
        s = floats(dtype, k)
        u = floats(dtype, rows * k).reshape(rows, k)
        sxv = floats(dtype, cols * k).reshape(cols, k)
        channels.append((s, u, sxv))
    assert pos == len(data)
    return {
        "names": names,
        "views": np.rad2deg(np.array(views)),
        "lights": np.rad2deg(lights[0]),
        "width": width,
        "height": height,
        "model": model,
        "channels": channels,
    }


def _independent_image(decoded, light: int, view: int) -> np.ndarray:
    """One (H, W, C) image from the independent decoding: row v * n_lights + l of the
    directions factor against the texels' factor, whichever of U and SxV each one is."""
    n_pairs = len(decoded["views"]) * len(decoded["lights"])
    n_texels = decoded["width"] * decoded["height"]
    row = view * len(decoded["lights"]) + light
    planes = []
    for _sigma, u, sxv in decoded["channels"]:
        if u.shape[0] == n_pairs and sxv.shape[0] == n_texels:  # abrdfs layout
            plane = sxv @ u[row]
        else:  # images layout: U = texels' factor, SxV = pairs' factor times sigma
            assert u.shape[0] == n_texels and sxv.shape[0] == n_pairs
            plane = u @ sxv[row]
        planes.append(plane.reshape(decoded["height"], decoded["width"]))
    return np.stack(planes, axis=2)


@pytest.mark.parametrize(
    "size, layout, scalar_size",
    [((4, 4), "abrdfs", 4), ((5, 7), "abrdfs", 8), ((5, 7), "images", 4), ((3, 6), "abrdfs", 2)],
)
def test_an_independent_reader_decodes_our_files_to_the_same_arrays(
    tmp_path, size, layout, scalar_size
):
    rng = np.random.default_rng(11)
    us, sigmas, sxvs = _factors(rng, *size)
    path = _write(
        tmp_path / "t.btf",
        us,
        sigmas,
        sxvs,
        layout=layout,
        scalar_size=scalar_size,
        channels=("Y", "U", "V"),
        color_model="YUV",
    )
    decoded = _independent_read(path)
    assert decoded["names"] == ["Y", "U", "V"] and decoded["model"] == 1  # btflib's YUV code
    assert (decoded["height"], decoded["width"]) == size
    np.testing.assert_allclose(decoded["lights"], LIGHTS, atol=1e-4)
    np.testing.assert_allclose(decoded["views"], VIEWS, atol=1e-4)
    tolerance = 2e-3 if scalar_size == 2 else 1e-5
    for c, (s, _, _) in enumerate(decoded["channels"]):
        np.testing.assert_allclose(s, sigmas[c], rtol=tolerance)
    ours = read_ubo2014(path)
    for light, view in [(0, 0), (5, 1), (7, 0), (2, 1)]:
        want = _truth(us, sxvs, light, view)
        theirs = _independent_image(decoded, light, view)
        scale = np.abs(want).max()
        assert np.abs(theirs - want).max() / scale < tolerance * 5
        assert np.abs(ours.image(light, view, rgb=False) - theirs).max() / scale < tolerance * 5


def test_images_layout_with_texels_equal_to_pairs_is_refused_not_misread(tmp_path):
    """D1: 16 texels and 16 direction pairs: no reader could tell the layouts apart."""
    us, sigmas, sxvs = _factors(np.random.default_rng(12), 4, 4)
    path = tmp_path / "t.btf"
    with pytest.raises(InputError, match="layout.*ambiguous"):
        _write(path, us, sigmas, sxvs, layout="images")
    assert not path.exists()


def test_half_floats_out_of_range_are_refused(tmp_path):
    """D2: float16 holds at most 65504; the writer used to store inf."""
    us, sigmas, sxvs = _factors(np.random.default_rng(13), 5, 7)
    sxvs[1] = sxvs[1] * 1e5
    path = tmp_path / "t.btf"
    with pytest.raises(InputError, match=r"eigentextures\[1\].*'G'.*65504"):
        _write(path, us, sigmas, sxvs, scalar_size=2)
    assert not path.exists()
    _write(path, us, sigmas, sxvs, scalar_size=4)  # float32 holds them
    assert np.isfinite(read_ubo2014(path).eigentextures).all()


def test_the_reader_refuses_infinite_values_in_a_factor(tmp_path):
    us, sigmas, sxvs = _factors(np.random.default_rng(14), 5, 7, ks=(2,))
    path = _write(tmp_path / "t.btf", us, sigmas, sxvs, scalar_size=2, channels=("L",))
    data = bytearray(path.read_bytes())
    data[-2:] = np.array([np.inf], "<f2").tobytes()  # the last SxV value
    path.write_bytes(bytes(data))
    with pytest.raises(InputError, match=r"t\.btf.*'L'.*SxV.*infinite"):
        read_ubo2014(path)


@pytest.mark.parametrize("shape", [(0, 4), (4, 0)])
def test_zero_sized_eigentextures_are_refused_by_name(tmp_path, shape):
    """D3: was a bare ValueError from numpy."""
    us, sigmas, _ = _factors(np.random.default_rng(15), 4, 4)
    sxvs = [np.zeros((*shape, len(s))) for s in sigmas]
    with pytest.raises(InputError, match=r"eigentextures\[0\].*height and width >= 1"):
        _write(tmp_path / "t.btf", us, sigmas, sxvs)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("name", ["Ä", "λ", "", "a\nb"])
def test_channel_names_must_be_printable_ascii(tmp_path, name):
    """D4: a non-latin-1 name was a UnicodeEncodeError."""
    us, sigmas, sxvs = _factors(np.random.default_rng(16), 4, 4)
    with pytest.raises(InputError, match=r"channels\[1\]"):
        _write(tmp_path / "t.btf", us, sigmas, sxvs, channels=("R", name, "B"))
    assert list(tmp_path.iterdir()) == []


def test_a_decorrelated_colour_model_needs_three_channels(tmp_path):
    """D5: a 1-channel YUV file was written and read; image() then failed in numpy."""
    us, sigmas, sxvs = _factors(np.random.default_rng(17), 4, 4, ks=(3,))
    path = tmp_path / "t.btf"
    with pytest.raises(InputError, match="color_model.*YUV.*3"):
        _write(path, us, sigmas, sxvs, channels=("Y",), color_model="YUV")
    assert not path.exists()
    # A file that says so anyway (written as RGB, model code patched to YUV) is refused.
    _write(path, us, sigmas, sxvs, channels=("Y",))
    data = bytearray(path.read_bytes())
    meta_end = 10 + struct.unpack_from("<I", data, 10)[0]
    model_at = meta_end + 4 + len(VIEWS) * (8 + 4 + 8 * len(LIGHTS)) + 8 + 4 + 4
    assert struct.unpack_from("<i", data, model_at)[0] == 0
    struct.pack_into("<i", data, model_at, 1)
    path.write_bytes(bytes(data))
    with pytest.raises(InputError, match=r"t\.btf.*color_model.*3 channels"):
        read_ubo2014(path)


@pytest.mark.parametrize("value, words", [(np.nan, "not finite"), (500.0, "theta 500")])
def test_directions_outside_the_hemisphere_are_refused(tmp_path, value, words):
    """A NaN light was accepted and then picked by render; theta 500 too."""
    lights = LIGHTS.copy()
    lights[3, 0] = value
    us, sigmas, sxvs = _factors(np.random.default_rng(18), 4, 4)
    kwargs = {"eigen_abrdfs": us, "singular_values": sigmas, "eigentextures": sxvs}
    with pytest.raises(InputError, match=f"light_dirs.*3.*{words}"):
        write_ubo2014(tmp_path / "t.btf", light_dirs=lights, view_dirs=VIEWS, **kwargs)
    # The same direction written into a valid file's bytes: the reader names it too.
    path = write_ubo2014(tmp_path / "t.btf", light_dirs=LIGHTS, view_dirs=VIEWS, **kwargs)
    data = bytearray(path.read_bytes())
    first_light = 10 + struct.unpack_from("<I", data, 10)[0] + 4 + 8 + 4
    struct.pack_into("<f", data, first_light + 8 * 3, np.deg2rad(value))
    path.write_bytes(bytes(data))
    with pytest.raises(InputError, match=f"t\\.btf.*light_dirs.*{words}"):
        read_ubo2014(path)
