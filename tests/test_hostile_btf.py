"""Hostile and faulty input on the BTF routes (issue #35): BTF files, photometric stereo,
the moving-average model, the experiment, extrapolation and rendering.

Every case runs the command in-process and asserts the exit code (2 for bad input), a
message naming the file or option, no traceback, and that every file under the inputs'
folders keeps its SHA-256 with no new file (nothing half-written).
"""

from __future__ import annotations

import hashlib
import shutil
import struct
from pathlib import Path

import numpy as np
import pytest

from data_gen.photometric import write_grey_sphere
from imagemap.btf import compress
from imagemap.btf.constraints import scanner_response
from imagemap.btf.extrapolate import constraint_images
from imagemap.btf.materials import make_material
from imagemap.btf.rendering import render_btf_matrix
from imagemap.btf.ubo2014 import write_ubo2014
from imagemap.cli import main
from imagemap.io import InputError, read_image, write_image

LIGHTS = np.array([[0, 0], [22, 0], [22, 90], [22, 180], [22, 270], [60, 45]], np.float32)
VIEWS = np.array([[0, 0], [30, 90]], np.float32)


def snapshot(*roots: Path) -> dict[str, str]:
    return {
        str(p): hashlib.sha256(p.read_bytes()).hexdigest()
        for root in roots
        for p in sorted(root.rglob("*"))
        if p.is_file()
    }


def cli(argv: list[str], capsys) -> tuple[int, str]:
    """Run the command in-process: (exit code, stderr + stdout); argparse's exits included."""
    try:
        code = main(argv)
    except SystemExit as exc:
        code = exc.code
    captured = capsys.readouterr()
    return code, captured.err + captured.out


def _sample(name: str, size: int, seed: int = 1):
    matrix = render_btf_matrix(make_material(name, size=size, seed=seed), LIGHTS, VIEWS)
    return matrix, compress(matrix, shape=(size, size), light_dirs=LIGHTS, view_dirs=VIEWS, k=24)


@pytest.fixture(scope="module")
def world(tmp_path_factory):
    """Valid inputs of every BTF command, made once: a 16x16 wallpaper sample and its model,
    a cloth sample, four 48 px scans, a UBO2014 file, a photometric set (a generated grey
    sphere, 128 x 85)."""
    root = tmp_path_factory.mktemp("hostile_btf")
    matrix, reference = _sample("wallpaper", 48)
    cols = (np.arange(16, 32)[:, None] * 48 + np.arange(16, 32)).ravel()
    sample = compress(matrix[:, cols], shape=(16, 16), light_dirs=LIGHTS, view_dirs=VIEWS, k=24)
    sample.save(root / "sample.npz")
    _sample("cloth", 16, seed=3)[1].save(root / "cloth.npz")
    scans = []
    for i, image in enumerate(constraint_images(reference)):
        scans.append(root / f"scan{i}.png")
        write_image(scans[-1], scanner_response(image, seed=i))
    assert (
        main(
            ["btf", "ma-fit", str(root / "sample.npz"), "-o", str(root / "model.npz")]
            + ["--levels", "2", "-q"]
        )
        == 0
    )
    ks = (3, 2, 2)
    rng = np.random.default_rng(0)
    n_pairs = len(LIGHTS) * len(VIEWS)
    write_ubo2014(
        root / "valid.btf",
        eigen_abrdfs=[np.linalg.qr(rng.normal(size=(n_pairs, k)))[0] for k in ks],
        singular_values=[np.ones(k) for k in ks],
        eigentextures=[rng.random((5, 7, k)) for k in ks],
        light_dirs=LIGHTS,
        view_dirs=VIEWS,
    )
    photometric = root / "psm"
    write_grey_sphere(photometric, seed=0)  # generated, psmImages' layout
    return {"root": root, "scans": [str(p) for p in scans], "psm": photometric}


def _ps(world, *extra, images=None) -> list[str]:
    psm = world["psm"]
    images = images or [str(psm / f"gray.{i}.png") for i in range(12)]
    return ["btf", "photometric", *images, "--lights", str(psm / "lights.txt"), *extra]


def _extrapolate(world, *extra, scans=None) -> list[str]:
    root = world["root"]
    scans = scans or world["scans"]
    return ["btf", "extrapolate", str(root / "sample.npz"), "--scans", *scans] + [
        "-o",
        str(root / "big.npz"),
        "-q",
        *extra,
    ]


# -- damaged inputs each case makes in its own folder --------------------------------------


def _ubo_bytes(world) -> bytearray:
    return bytearray((world["root"] / "valid.btf").read_bytes())


def _first_light_offset(data: bytes) -> int:
    return 10 + struct.unpack_from("<I", data, 10)[0] + 4 + 8 + 4  # meta, n_views, view, n


def _btf_nan_light(world, folder):
    data = _ubo_bytes(world)
    struct.pack_into("<f", data, _first_light_offset(data) + 8 * 2, np.nan)
    (folder / "nan_light.btf").write_bytes(bytes(data))
    return folder / "nan_light.btf"


def _btf_theta_500(world, folder):
    data = _ubo_bytes(world)
    struct.pack_into("<f", data, _first_light_offset(data) + 8 * 4, np.deg2rad(500.0))
    (folder / "theta500.btf").write_bytes(bytes(data))
    return folder / "theta500.btf"


def _btf_truncated(world, folder):
    (folder / "short.btf").write_bytes(bytes(_ubo_bytes(world)[:-40]))
    return folder / "short.btf"


def _btf_infinite(world, folder):
    data = _ubo_bytes(world)
    data[-4:] = np.array([np.inf], "<f4").tobytes()
    (folder / "inf.btf").write_bytes(bytes(data))
    return folder / "inf.btf"


def _btf_yuv_one_channel(world, folder):
    rng = np.random.default_rng(1)
    path = write_ubo2014(
        folder / "grey.btf",
        eigen_abrdfs=[np.linalg.qr(rng.normal(size=(12, 2)))[0]],
        singular_values=[np.ones(2)],
        eigentextures=[rng.random((4, 4, 2))],
        light_dirs=LIGHTS,
        view_dirs=VIEWS,
        channels=("Y",),
    )
    data = bytearray(path.read_bytes())
    meta_end = _first_light_offset(data) - 16
    model_at = meta_end + 4 + len(VIEWS) * (12 + 8 * len(LIGHTS)) + 8 + 4 + 4
    assert struct.unpack_from("<i", data, model_at)[0] == 0  # RGB, patched to YUV
    struct.pack_into("<i", data, model_at, 1)
    path.write_bytes(bytes(data))
    return path


def _model_offset(data: bytes) -> int:
    """Where the colour model's code is in ``valid.btf`` (the components field before it,
    the colour mean after it)."""
    meta_end = _first_light_offset(data) - 16
    return meta_end + 4 + len(VIEWS) * (12 + 8 * len(LIGHTS)) + 8 + 4 + 4


def _btf_trailing_junk(world, folder):
    (folder / "junk.btf").write_bytes(bytes(_ubo_bytes(world)) + b"trailing junk")
    return folder / "junk.btf"


def _btf_components_1000(world, folder):
    data = _ubo_bytes(world)
    assert struct.unpack_from("<I", data, _model_offset(data) - 4)[0] == 3  # the largest k
    struct.pack_into("<I", data, _model_offset(data) - 4, 1000)
    (folder / "k1000.btf").write_bytes(bytes(data))
    return folder / "k1000.btf"


def _btf_nan_colour_mean(world, folder):
    data = _ubo_bytes(world)
    struct.pack_into("<f", data, _model_offset(data) + 4, np.nan)
    (folder / "nan_mean.btf").write_bytes(bytes(data))
    return folder / "nan_mean.btf"


def _npz_nan_view(world, folder):
    from imagemap.btf import load_btf

    btf = load_btf(world["root"] / "sample.npz")
    arrays = {
        "eigen_abrdfs": btf.eigen_abrdfs,
        "singular_values": btf.singular_values,
        "eigentextures": btf.eigentextures,
        "light_dirs": btf.light_dirs,
        "view_dirs": np.array([[0, 0], [np.nan, 90]], np.float32),
    }
    np.savez(folder / "nan_view.npz", **arrays)
    return folder / "nan_view.npz"


def _not_a_btf(world, folder):
    np.savez(folder / "other.npz", a=np.zeros(3))
    return folder / "other.npz"


BTF_FILE_CASES = {
    # case: (maker of the damaged file, words the message must contain besides its name)
    "UBO2014 file with a NaN light direction": (_btf_nan_light, "not finite"),
    "UBO2014 file with theta 500": (_btf_theta_500, "theta 500"),
    "UBO2014 file cut short": (_btf_truncated, "truncated"),
    "UBO2014 file with an infinite factor value": (_btf_infinite, "infinite"),
    "UBO2014 file: one channel in YUV": (_btf_yuv_one_channel, "color_model"),
    "UBO2014 file with trailing junk (#45)": (_btf_trailing_junk, "13 bytes after the last"),
    "UBO2014 file whose components field says 1000 (#45)": (
        _btf_components_1000,
        "components field says 1000",
    ),
    "UBO2014 file with a NaN colour mean (#45)": (_btf_nan_colour_mean, "colour mean"),
    ".npz BTF with a NaN view direction": (_npz_nan_view, "view_dirs"),
    ".npz that is not a BTF": (_not_a_btf, "not a BTF"),
}


@pytest.mark.parametrize("case", sorted(BTF_FILE_CASES))
def test_damaged_btf_files_are_refused_by_name(world, tmp_path, capsys, case):
    make, words = BTF_FILE_CASES[case]
    path = make(world, tmp_path)
    before = snapshot(world["root"], tmp_path)
    out = tmp_path / "relit.png"
    code, message = cli(["btf", "render", str(path), "-o", str(out)], capsys)
    assert code == 2 and path.name in message and words in message, message
    assert "Traceback" not in message
    assert snapshot(world["root"], tmp_path) == before


def test_write_ubo2014_refuses_a_folder_and_a_channel_float16_would_lose(tmp_path, caplog):
    """A folder as the path was a bare IsADirectoryError; singular values of 1e-9 in float16
    read back as [0, 0] without a word (overflow was refused)."""
    factors = {
        "eigen_abrdfs": [np.eye(2)],
        "eigentextures": [np.ones((2, 3, 2))],
        "channels": ("L",),
        "light_dirs": [[0, 0], [45, 90]],
        "view_dirs": [[0, 0]],
    }
    (tmp_path / "folder").mkdir()
    with pytest.raises(InputError, match="folder: write_ubo2014 path is a directory"):
        write_ubo2014(tmp_path / "folder", singular_values=[[1.0, 0.5]], **factors)
    with pytest.raises(InputError, match=r"singular_values\[0\].*2 of 2 component.*lost"):
        write_ubo2014(tmp_path / "t.btf", singular_values=[[1e-9, 1e-9]], scalar_size=2, **factors)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["folder"]
    with caplog.at_level("WARNING", logger="imagemap"):
        write_ubo2014(tmp_path / "t.btf", singular_values=[[1.0, 1e-9]], scalar_size=2, **factors)
    assert "1 of 2 component(s)" in caplog.text


def test_write_image_refuses_nan(tmp_path):
    """An all-NaN array was written as a black PNG."""
    with pytest.raises(InputError, match=r"x\.png: the image has 12 NaN value\(s\) of 12"):
        write_image(tmp_path / "x.png", np.full((3, 4), np.nan))
    assert not list(tmp_path.iterdir())


# -- photometric stereo ------------------------------------------------------------------------


def _lights_file(folder: Path, text: str) -> str:
    (folder / "l.txt").write_text(text)
    return str(folder / "l.txt")


PHOTOMETRIC_CASES = {
    "an image given twice": (
        lambda w, f: _ps(
            w, "-o", str(f / "n.png"), images=[str(w["psm"] / f"gray.{i}.png") for i in (0, 1, 1)]
        ),
        ["gray.1.png", "twice"],
    ),
    "two images": (
        lambda w, f: _ps(
            w, "-o", str(f / "n.png"), images=[str(w["psm"] / f"gray.{i}.png") for i in (0, 1)]
        ),
        ["images", "3 or more"],
    ),
    "11 lights for 12 images": (
        lambda w, f: (
            _ps(w, "-o", str(f / "n.png"))[:-2]
            + ["--lights", _lights_file(f, "0 0 1\n" * 11), "-o", str(f / "n.png")]
        ),
        ["--lights", "11 lights for 12"],
    ),
    "a NaN light": (
        lambda w, f: (
            _ps(w, "-o", str(f / "n.png"))[:-2]
            + ["--lights", _lights_file(f, "0 0 1\n" * 5 + "nan 0 1\n" + "0 0 1\n" * 6)]
            + ["-o", str(f / "n.png")]
        ),
        ["l.txt:6", "not finite"],
    ),
    "a light behind the surface": (
        lambda w, f: (
            _ps(w, "-o", str(f / "n.png"))[:-2]
            + ["--lights", _lights_file(f, "0 0 1\n" * 11 + "0.5 0 -1\n"), "-o", str(f / "n.png")]
        ),
        ["l.txt:12", "camera side"],
    ),
    "-o is an input image": (
        lambda w, f: _ps(w, "-o", str(w["psm"] / "gray.3.png")),
        ["gray.3.png", "would overwrite"],
    ),
    "--height with a wrong suffix": (
        lambda w, f: _ps(w, "-o", str(f / "n.png"), "--height", str(f / "h.jpg")),
        ["--height", "h.jpg"],
    ),
    "--height and -o the same file": (
        lambda w, f: _ps(w, "-o", str(f / "n.png"), "--height", str(f / "n.png")),
        ["n.png", "same file"],
    ),
    "a mask of another size": (
        lambda w, f: _ps(w, "-o", str(f / "n.png"), "--mask", str(_image(f / "m.png", (8, 8)))),
        ["m.png", "mask is 8x8"],
    ),
    "a black mask": (
        lambda w, f: _ps(w, "-o", str(f / "n.png"), "--mask", str(_image(f / "m.png", (85, 128)))),
        ["m.png", "selects no pixel"],
    ),
    "an image of another size": (
        lambda w, f: _ps(
            w,
            "-o",
            str(f / "n.png"),
            images=[
                *(str(w["psm"] / f"gray.{i}.png") for i in range(11)),
                str(_image(f / "small.png", (40, 60), 0.5)),
            ],
        ),
        ["small.png", "must match"],
    ),
    "a black image": (
        lambda w, f: _ps(
            w,
            "-o",
            str(f / "n.png"),
            images=[
                *(str(w["psm"] / f"gray.{i}.png") for i in range(11)),
                str(_image(f / "black.png", (85, 128))),
            ],
        ),
        ["black.png", "black"],
    ),
    "alpha that covers nothing": (
        lambda w, f: _ps(w, "-o", str(f / "n.png"), images=_transparent(w, f)),
        ["alpha", "covers no pixel"],
    ),
    "--saturation-level under --shadow-level": (
        lambda w, f: _ps(w, "-o", str(f / "n.png"), "--saturation-level", "0.001"),
        ["--saturation-level", "--shadow-level"],
    ),
    "--shadow-level nan": (
        lambda w, f: _ps(w, "-o", str(f / "n.png"), "--shadow-level", "nan"),
        ["--shadow-level"],
    ),
    "--gamma 0": (lambda w, f: _ps(w, "-o", str(f / "n.png"), "--gamma", "0"), ["--gamma"]),
    # #45: lights that decide no normal, samples that say nothing.
    "12 identical lights": (
        lambda w, f: _ps_lights(w, f, "0.3 0.4 0.866\n" * 12),
        ["--lights", "l.txt", "rank 1 < 3", "one direction"],
    ),
    "12 lights in one plane through the camera (collinear)": (
        lambda w, f: _ps_lights(
            w, f, "".join(f"{np.cos(a):.6f} 0 {np.sin(a):.6f}\n" for a in np.linspace(0.5, 1.5, 12))
        ),
        ["--lights", "l.txt", "rank 2 < 3", "one plane"],
    ),
    "12 all-saturated images": (
        lambda w, f: _ps(
            w,
            "-o",
            str(f / "n.png"),
            "--height",
            str(f / "h.npy"),
            images=[str(_image(f / f"white{i:02d}.png", (85, 128), 1.0)) for i in range(12)],
        ),
        ["no pixel has 3 usable samples", "saturated"],
    ),
}


def _ps_lights(world, folder, text: str) -> list[str]:
    """The grey sphere's images with another lights file, normals and heights asked for."""
    argv = _ps(world, "-o", str(folder / "n.png"), "--height", str(folder / "h.npy"))
    lights = argv.index("--lights") + 1
    argv[lights] = _lights_file(folder, text)
    return argv


def _image(path: Path, shape, value: float = 0.0) -> Path:
    return write_image(path, np.full(shape, value))


def _transparent(world, folder) -> list[str]:
    """The 12 images with an alpha channel that is 0 everywhere."""
    paths = []
    for i in range(12):
        grey = read_image(world["psm"] / f"gray.{i}.png")[..., 0]
        paths.append(
            str(
                write_image(
                    folder / f"t{i:02d}.png", np.dstack([grey, grey, grey, np.zeros_like(grey)])
                )
            )
        )
    return paths


@pytest.mark.parametrize("case", sorted(PHOTOMETRIC_CASES))
def test_photometric_refuses_bad_input_before_any_work(world, tmp_path, capsys, case):
    build, words = PHOTOMETRIC_CASES[case]
    argv = build(world, tmp_path)
    before = snapshot(world["root"], tmp_path)
    code, message = cli(argv, capsys)
    assert code == 2, message
    for word in words:
        assert word in message, message
    assert "Traceback" not in message
    assert snapshot(world["root"], tmp_path) == before


def test_photometric_leaves_out_pixels_without_three_usable_samples(world, tmp_path, caplog):
    """A patch saturated in 10 of 12 images keeps 2 usable samples: its pixels are left out
    of the normals (transparent in the normal map, NaN heights) with a warning giving their
    share, not filled with a constant; the rest is solved as before."""
    psm, mask = world["psm"], read_image(world["psm"] / "mask.png")[..., 0] > 0.5
    patch = np.zeros_like(mask)
    patch[35:45, 55:70] = True
    assert mask[patch].all()
    images = []
    for i in range(12):
        grey = read_image(psm / f"gray.{i}.png")[..., 0]
        grey[patch] = 1.0 if i < 10 else grey[patch]
        images.append(str(write_image(tmp_path / f"g{i:02d}.png", grey)))
    out, height = tmp_path / "n.png", tmp_path / "h.npy"
    argv = _ps(world, "-o", str(out), "--height", str(height), "--mask", str(psm / "mask.png"))
    with caplog.at_level("WARNING", logger="imagemap"):
        assert main([*argv[:2], *images, *argv[14:], "-q"]) == 0
    share = 100 * patch.sum() / mask.sum()
    assert f"{patch.sum()} of {mask.sum()} pixels ({share:.1f} %) left out" in caplog.text
    import imageio.v3 as iio

    normal_map = iio.imread(out)
    assert normal_map.shape[2] == 4
    np.testing.assert_array_equal(normal_map[..., 3] > 127, mask & ~patch)
    heights = np.load(height)
    assert np.isnan(heights[patch]).all() and np.isfinite(heights[mask & ~patch]).all()


def test_photometric_warns_about_ill_conditioned_lights_with_the_figure(world, tmp_path, caplog):
    """12 distinct lights within 1.5 degrees of the view: rank 3 but a condition number
    near 54, over MAX_LIGHT_CONDITION: a warning with the figure; the run goes on."""
    from imagemap.btf.photometric import MAX_LIGHT_CONDITION

    angle = np.deg2rad(1.5)
    text = "".join(
        f"{np.sin(angle) * np.cos(a):.6f} {np.sin(angle) * np.sin(a):.6f} {np.cos(angle):.6f}\n"
        for a in np.linspace(0, 2 * np.pi, 12, endpoint=False)
    )
    with caplog.at_level("WARNING", logger="imagemap"):
        assert main([*_ps_lights(world, tmp_path, text), "-q"]) == 0
    assert "l.txt: the light matrix' condition number is 54." in caplog.text, caplog.text
    assert f"over {MAX_LIGHT_CONDITION:g}" in caplog.text


def test_photometric_api_refuses_rank_two_and_leaves_out_undecided_pixels():
    from imagemap.btf.photometric import photometric_stereo

    plane = np.array([[np.cos(a), 0.0, np.sin(a)] for a in (0.4, 0.8, 1.2, 1.5)])
    with pytest.raises(InputError, match=r"light_dirs: .*rank 2 < 3"):
        photometric_stereo(np.ones((4, 3, 3)), plane)
    lights = np.array([[0, 0, 1], [0.6, 0, 0.8], [0, 0.6, 0.8], [-0.6, 0, 0.8]])
    images = np.full((4, 2, 2), 0.5) * lights[:, 2, None, None]
    images[1:, 0, 0] = 0.0  # one lit sample left at (0, 0)
    normals, albedo = photometric_stereo(images, lights)
    assert np.isnan(normals[0, 0]).all() and np.isnan(albedo[0, 0]).all()
    np.testing.assert_allclose(normals[1, 1], [0, 0, 1], atol=1e-6)


def test_photometric_rgba_alpha_is_the_mask(world, tmp_path, capsys):
    """RGBA input is accepted with alpha as the mask: same normals as grey + --mask."""
    mask = read_image(world["psm"] / "mask.png")[..., 0]
    rgba = []
    for i in range(12):
        grey = read_image(world["psm"] / f"gray.{i}.png")[..., 0]
        rgba.append(str(write_image(tmp_path / f"c{i:02d}.png", np.dstack([grey] * 3 + [mask]))))
    assert main(_ps(world, "-o", str(tmp_path / "a.png"), "-q", images=rgba)) == 0
    assert (
        main(
            _ps(
                world, "-o", str(tmp_path / "b.png"), "--mask", str(world["psm"] / "mask.png"), "-q"
            )
        )
        == 0
    )
    a, b = read_image(tmp_path / "a.png"), read_image(tmp_path / "b.png")
    assert np.abs(a - b).max() <= 1 / 255 + 1e-6


# -- the moving-average model -------------------------------------------------------------------

MA_CASES = {
    "ma-fit --levels 50 on a 16x16 sample": (
        lambda w, f: [
            "btf",
            "ma-fit",
            str(w["root"] / "sample.npz"),
            "-o",
            str(f / "m.npz"),
            "--levels",
            "50",
        ],
        ["--levels", "sample.npz", "at most 2"],
    ),
    "ma-fit --bump-scale nan": (
        lambda w, f: [
            "btf",
            "ma-fit",
            str(w["root"] / "sample.npz"),
            "-o",
            str(f / "m.npz"),
            "--levels",
            "2",
            "--bump-scale",
            "nan",
        ],
        ["--bump-scale"],
    ),
    "ma-synthesize with another material's sample": (
        lambda w, f: [
            "btf",
            "ma-synthesize",
            str(w["root"] / "model.npz"),
            "-o",
            str(f / "b.npz"),
            "--sample",
            str(w["root"] / "cloth.npz"),
            "--size",
            "32",
            "32",
        ],
        ["--sample", "cloth.npz", "not the BTF the model"],
    ),
    "ma-synthesize of a size no memory holds": (
        lambda w, f: [
            "btf",
            "ma-synthesize",
            str(w["root"] / "model.npz"),
            "-o",
            str(f / "b.png"),
            "--size",
            "200000",
            "200000",
        ],
        ["--size 200000 200000", "memory"],
    ),
    "ma-synthesize from a damaged model": (
        lambda w, f: ["btf", "ma-synthesize", str(_damaged_model(w, f)), "-o", str(f / "b.png")],
        ["damaged.npz", "damaged"],
    ),
}


def _damaged_model(world, folder) -> Path:
    with np.load(world["root"] / "model.npz") as data:
        arrays = {k: data[k] for k in data.files if k != "kl_bases"}
    np.savez(folder / "damaged.npz", **arrays)
    return folder / "damaged.npz"


@pytest.mark.parametrize("case", sorted(MA_CASES))
def test_moving_average_commands_refuse_bad_input(world, tmp_path, capsys, case):
    build, words = MA_CASES[case]
    argv = build(world, tmp_path) + ["-q"]
    before = snapshot(world["root"], tmp_path)
    code, message = cli(argv, capsys)
    assert code == 2, message
    for word in words:
        assert word in message, message
    assert "Traceback" not in message
    assert snapshot(world["root"], tmp_path) == before


def test_memory_guard_honours_rlimit_as(world, tmp_path, capsys, monkeypatch):
    """An address-space limit (ulimit -v) counts, not only the free memory."""
    import resource

    from imagemap import memory

    unlimited = memory.available_memory()
    status = Path("/proc/self/status").read_text() if Path("/proc/self/status").exists() else ""
    vm_size = next(
        (int(l.split()[1]) * 1024 for l in status.splitlines() if l.startswith("VmSize")), 0
    )
    monkeypatch.setattr(resource, "getrlimit", lambda which: (vm_size + 50 * 2**20, -1))
    room = memory.available_memory()
    assert room is not None and room <= 50 * 2**20 and (unlimited is None or room < unlimited)
    argv = ["btf", "ma-synthesize", str(world["root"] / "model.npz"), "-o", str(tmp_path / "b.png")]
    before = snapshot(world["root"], tmp_path)
    code, message = cli([*argv, "--size", "1024", "1024", "-q"], capsys)  # about 200 MB
    assert code == 2 and "--size 1024 1024" in message and "available" in message, message
    assert snapshot(world["root"], tmp_path) == before


# -- the experiment -----------------------------------------------------------------------------

EXPERIMENT_CASES = {
    "--sample-size larger than --size": (["--size", "32", "--sample-size", "64"], "--sample-size"),
    "--sample-size equal to --size": (["--size", "32", "--sample-size", "32"], "--sample-size"),
    "--size 8": (["--size", "8"], "--size"),
    "unknown material": (["--materials", "marble"], "--materials"),
    "unknown method": (["--methods", "magic"], "--methods"),
    "--out is an existing file": (["--out-is-file"], "afile"),
}


@pytest.mark.parametrize("case", sorted(EXPERIMENT_CASES))
def test_experiment_refuses_bad_options_before_any_work(world, tmp_path, capsys, monkeypatch, case):
    import imagemap.btf.experiment as experiment

    def no_work(*args, **kwargs):
        raise AssertionError("a material was rendered before the options were checked")

    monkeypatch.setattr(experiment, "prepare_material", no_work)
    extra, words = EXPERIMENT_CASES[case]
    (tmp_path / "afile").write_text("keep me")
    out = tmp_path / "afile" if extra == ["--out-is-file"] else tmp_path / "table"
    extra = [] if extra == ["--out-is-file"] else extra
    before = snapshot(world["root"], tmp_path)
    code, message = cli(["btf", "experiment", "--out", str(out), "-q", *extra], capsys)
    assert code == 2 and words in message and "Traceback" not in message, message
    assert snapshot(world["root"], tmp_path) == before


# -- extrapolation and rendering ------------------------------------------------------------------


def _black_scan(world, folder) -> list[str]:
    return [*world["scans"][:3], str(_image(folder / "black.png", (48, 48, 3)))]


def _copied_scan(world, folder) -> list[str]:
    shutil.copy(world["scans"][1], folder / "copy.png")
    return [world["scans"][0], world["scans"][1], str(folder / "copy.png"), world["scans"][3]]


EXTRAPOLATE_CASES = {
    "an all-black scan": (lambda w, f: _extrapolate(w, scans=_black_scan(w, f)), ["black.png"]),
    "one scan given four times": (
        lambda w, f: _extrapolate(w, scans=[w["scans"][0]] * 4),
        ["--scans", "scan0.png", "twice"],
    ),
    "the same scan under two names": (
        lambda w, f: _extrapolate(w, scans=_copied_scan(w, f)),
        ["copy.png", "scan1.png", "same image"],
    ),
    "--ws 0 --wc 0": (lambda w, f: _extrapolate(w, "--ws", "0", "--wc", "0"), ["--ws", "--wc"]),
    "--wc 0 with the pixel-wise default --ws 0": (
        lambda w, f: _extrapolate(w, "--wc", "0"),
        ["--wc", "both 0"],
    ),
    "a sample with a NaN view direction": (
        lambda w, f: [
            "btf",
            "extrapolate",
            str(_npz_nan_view(w, f)),
            "--scans",
            *w["scans"],
            "-o",
            str(f / "big.npz"),
        ],
        ["nan_view.npz", "view_dirs"],
    ),
    "render --light 500 0": (
        lambda w, f: [
            "btf",
            "render",
            str(w["root"] / "sample.npz"),
            "-o",
            str(f / "r.png"),
            "--light",
            "500",
            "0",
        ],
        ["--light"],
    ),
    "render -o is the BTF": (
        lambda w, f: [
            "btf",
            "render",
            str(w["root"] / "sample.npz"),
            "-o",
            str(w["root"] / "sample.npz"),
        ],
        ["sample.npz", "-o"],
    ),
}


@pytest.mark.parametrize("case", sorted(EXTRAPOLATE_CASES))
def test_extrapolate_and_render_refuse_bad_input(world, tmp_path, capsys, case):
    build, words = EXTRAPOLATE_CASES[case]
    argv = build(world, tmp_path)
    before = snapshot(world["root"], tmp_path)
    code, message = cli(argv, capsys)
    assert code == 2, message
    for word in words:
        assert word in message, message
    assert "Traceback" not in message
    assert snapshot(world["root"], tmp_path) == before


def test_extrapolate_refuses_a_scan_of_another_material(tmp_path, capsys, caplog):
    """--register: a foreign scan is refused by name with its confidence, nothing written
    (#45: it was a warning, and the result was written); --allow-misfit goes on with the
    warning."""
    import tifffile
    from scipy import ndimage
    from skimage.transform import rotate

    size, crop = 160, 112
    lights = np.array([[22.0, a] for a in (0, 90, 180, 270)], np.float32)
    top = np.array([[0.0, 0.0]], np.float32)

    def images_of(name, seed):
        matrix = render_btf_matrix(make_material(name, size=size, seed=seed), lights, top)
        return [
            matrix[3 * i : 3 * i + 3].reshape(3, size, size).transpose(1, 2, 0) for i in range(4)
        ]

    # As tests/test_btf_registration.py: lamp fixed, the sample turned, rotated, shifted.
    cloth, wood = images_of("cloth", 2), images_of("wood", 11)
    order, angles = [2, 0, 3, 1], [0.0, 3.0, -2.5, 1.5]
    shifts = [(0.0, 0.0), (-2.5, 4.0), (3.0, -1.5), (1.0, 3.5)]
    paths, c = [], (size - crop) // 2
    for i, (azimuth, angle, shift) in enumerate(zip(order, angles, shifts, strict=True)):
        image = np.rot90((wood if i == 3 else cloth)[azimuth], azimuth)
        image = rotate(image, angle, order=3, mode="reflect")
        image = ndimage.shift(image, (*shift, 0), order=3, mode="reflect")[
            c : c + crop, c : c + crop
        ]
        paths.append(str(tmp_path / f"s{i}.tif"))  # float TIFF: the very values registered
        tifffile.imwrite(
            paths[-1], np.clip(0.9 * image, 0, 1).astype(np.float32), photometric="rgb"
        )
    matrix = render_btf_matrix(make_material("cloth", size=32, seed=2), LIGHTS, VIEWS)
    sample = compress(matrix, shape=(32, 32), light_dirs=LIGHTS, view_dirs=VIEWS, k=12)
    sample.save(tmp_path / "sample.npz")
    argv = ["btf", "extrapolate", str(tmp_path / "sample.npz"), "--scans", *paths]
    argv += ["--register", "--linear-scans", "-o", str(tmp_path / "b.npz")]
    before = snapshot(tmp_path)
    code, message = cli(argv, capsys)
    assert code == 2, message
    assert f"--scans: {paths[3]} (match confidence " in message and "--allow-misfit" in message
    assert snapshot(tmp_path) == before
    with caplog.at_level("WARNING", logger="imagemap"):
        code, message = cli([*argv, "--allow-misfit"], capsys)
    assert code == 0, message
    warnings = caplog.text  # the command's log lines (stderr outside pytest)
    assert "--scans " + paths[3] + " does not fit" in warnings, warnings
    assert "s1.tif does not fit" not in warnings and "s2.tif does not fit" not in warnings
