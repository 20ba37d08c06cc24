import numpy as np
import pytest

from imagemap.io import InputError, atomic_path, read_depth, read_image, write_image


def test_depth_8_and_16_bit_and_npy_agree(tmp_path):
    depth = np.zeros((20, 30), np.float32)
    depth[5:15, 5:25] = np.linspace(0.2, 1.0, 20)[None, :]
    write_image(tmp_path / "d16.png", np.round(depth * 65535).astype(np.uint16))
    write_image(tmp_path / "d8.png", np.round(depth * 255).astype(np.uint8))
    np.save(tmp_path / "d.npy", np.where(depth > 0, depth, np.nan))
    d16, d8, dn = (read_depth(tmp_path / n) for n in ("d16.png", "d8.png", "d.npy"))
    np.testing.assert_allclose(d16, depth, atol=1e-4)
    np.testing.assert_allclose(d8, depth, atol=3e-3)
    np.testing.assert_array_equal(dn, depth)  # NaN became background 0


@pytest.mark.parametrize(
    "array, message",
    [
        (np.zeros((20, 20), np.float32), "no foreground"),
        (np.full((20, 20), -1, np.float32), "negative"),
        (np.ones((20, 20, 2, 2), np.float32), "one channel"),
        (np.ones((4, 4), np.float32), "too small"),
    ],
)
def test_bad_depth(tmp_path, array, message):
    path = tmp_path / "bad_depth.npy"
    np.save(path, array)
    with pytest.raises(InputError, match=message) as info:
        read_depth(path)
    assert "bad_depth.npy" in str(info.value)


def test_unreadable_and_unsupported(tmp_path):
    junk = tmp_path / "junk.png"
    junk.write_bytes(b"not a png")
    with pytest.raises(InputError, match="junk.png"):
        read_image(junk)
    with pytest.raises(InputError, match="unsupported depth format"):
        read_depth(tmp_path / "x.bmp")


def test_write_is_atomic_on_failure(tmp_path):
    target = tmp_path / "out.png"
    with pytest.raises(ValueError):
        write_image(target, np.zeros((4, 4, 7)))  # 7 channels cannot be a PNG
    write_image(target, np.zeros((4, 4, 3)))
    before = target.read_bytes()
    with pytest.raises(RuntimeError), atomic_path(target) as tmp:
        tmp.write_bytes(b"half")
        raise RuntimeError("interrupted")
    assert target.read_bytes() == before  # the old file is untouched
    assert [p.name for p in tmp_path.iterdir()] == ["out.png"]  # no temporary left


def test_outputs_get_the_usual_file_mode(tmp_path):
    import os
    import stat

    umask = os.umask(0o022)
    try:
        path = write_image(tmp_path / "mode.png", np.zeros((4, 4, 3)))
    finally:
        os.umask(umask)
    assert stat.S_IMODE(path.stat().st_mode) == 0o644


def _png_kinds(folder):
    """PNGs of every kind Pillow writes, made by Pillow itself (not by imagemap)."""
    from PIL import Image

    rng = np.random.default_rng(0)
    rgb = rng.integers(0, 256, (9, 11, 3), np.uint8)
    made = {
        "grey": Image.fromarray(rgb[..., 0]),
        "grey_alpha": Image.fromarray(rgb[..., :2].copy(), mode="LA"),
        "rgb": Image.fromarray(rgb),
        "rgba": Image.fromarray(np.dstack([rgb, rgb[..., :1]])),
        "palette": Image.fromarray(rgb).quantize(colors=7),
        "bilevel": Image.fromarray(rgb[..., 0] > 127),
        "grey16": Image.fromarray(rng.integers(0, 65536, (9, 11)).astype(np.uint16)),
    }
    transparent = made["palette"].copy()
    transparent.info["transparency"] = 2
    made["palette_transparent"] = transparent
    paths = {}
    for name, image in made.items():
        paths[name] = folder / f"{name}.png"
        image.save(paths[name])
    return paths


def test_pngs_read_without_imageio_are_imageios_arrays(tmp_path):
    # Pillow alone reads a PNG (no imageio import at start-up): the same values, dtype
    # and layout as imageio's Pillow plugin, for every kind of PNG; writes the same bytes.
    import imageio.v3 as iio

    from imagemap import io

    for name, path in _png_kinds(tmp_path).items():
        expected = iio.imread(path)
        got = io._read_png(path)
        assert got is not None and got.dtype == expected.dtype, name
        assert got.flags.writeable, name
        np.testing.assert_array_equal(got, expected, err_msg=name)
        if got.ndim == 2 or got.shape[-1] in (3, 4):
            iio.imwrite(tmp_path / "by_imageio.png", got, extension=".png")
            io._write_png(tmp_path / "by_pillow.png", got)
            by_imageio, by_pillow = (tmp_path / f"by_{w}.png" for w in ("imageio", "pillow"))
            assert by_pillow.read_bytes() == by_imageio.read_bytes(), name
    (tmp_path / "noise.png").write_bytes(b"\x89PNG not really")
    assert io._read_png(tmp_path / "noise.png") is None  # left to imageio, as before
