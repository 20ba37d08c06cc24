"""BTF extrapolation: the compressed BTF, the constraint pipeline, both methods, UBO2014."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from imagemap.btf import BTF, compress, relative_error
from imagemap.btf.constraints import (
    align_histograms,
    color_correct,
    constraint_bands,
    histogram_alignment_factors,
    scanner_response,
    stack_neighbourhood,
    surface_descriptors,
)
from imagemap.btf.extrapolate import (
    PixelwiseParams,
    TextureOptimizationParams,
    constraint_images,
    pixelwise,
    prepare_scans,
    texture_optimization,
    tile,
)
from imagemap.io import InputError

LIGHTS = np.array([[0, 0], [22, 0], [22, 90], [22, 180], [22, 270], [60, 45]], np.float32)
VIEWS = np.array([[0, 0], [45, 90]], np.float32)


def _random_btf(rng, shape=(12, 10), k=8) -> BTF:
    n_rows = len(LIGHTS) * len(VIEWS) * 3
    matrix = rng.random((n_rows, shape[0] * shape[1]), dtype=np.float32)
    return compress(matrix, shape=shape, light_dirs=LIGHTS, view_dirs=VIEWS, k=k)


# --------------------------------------------------------------------------- core
def test_compress_is_exact_at_full_rank_and_one_image_is_its_rows():
    rng = np.random.default_rng(0)
    n_rows = len(LIGHTS) * len(VIEWS) * 3
    matrix = rng.random((n_rows, 8 * 9), dtype=np.float32)
    btf = compress(matrix, shape=(8, 9), light_dirs=LIGHTS, view_dirs=VIEWS, k=n_rows)
    np.testing.assert_allclose(btf.matrix(), matrix, atol=2e-5)
    np.testing.assert_allclose(btf.eigen_abrdfs.T @ btf.eigen_abrdfs, np.eye(n_rows), atol=1e-5)
    light, view = 3, 1
    rows = (light * len(VIEWS) + view) * 3 + np.arange(3)
    image = btf.image(light, view)
    np.testing.assert_allclose(np.moveaxis(image, 2, 0).reshape(3, -1), matrix[rows], atol=2e-5)
    # ...and the same from the factors: U[rows] (V Sigma)^T.
    expected = btf.eigen_abrdfs[rows] @ btf.eigentextures.reshape(-1, btf.n_components).T
    np.testing.assert_allclose(np.moveaxis(image, 2, 0).reshape(3, -1), expected, atol=1e-6)


def test_randomized_and_gram_compression_agree():
    rng = np.random.default_rng(1)
    low_rank = rng.random((36, 5)) @ rng.random((5, 120))
    matrix = low_rank.astype(np.float32)
    gram = compress(matrix, shape=(10, 12), light_dirs=LIGHTS, view_dirs=VIEWS, k=5)
    randomized = compress(
        matrix, shape=(10, 12), light_dirs=LIGHTS, view_dirs=VIEWS, k=5, method="randomized"
    )
    np.testing.assert_allclose(gram.singular_values, randomized.singular_values, rtol=1e-4)
    assert relative_error(gram, randomized, decompress=True) < 1e-3


def test_save_load_round_trip(tmp_path):
    btf = _random_btf(np.random.default_rng(2))
    path = btf.save(tmp_path / "b.npz")
    loaded = BTF.load(path)
    for name in ("eigen_abrdfs", "singular_values", "eigentextures", "light_dirs", "view_dirs"):
        np.testing.assert_array_equal(getattr(loaded, name), getattr(btf, name))
    assert loaded.channels == btf.channels and loaded.color_model == btf.color_model
    (tmp_path / "bad.npz").write_bytes(b"not a zip")
    with pytest.raises(InputError, match="bad.npz"):
        BTF.load(tmp_path / "bad.npz")


def test_compressed_domain_error_equals_decompressed_error():
    rng = np.random.default_rng(3)
    reference = _random_btf(rng, k=10)
    # Shared U: only the eigentextures differ.
    noisy = reference.with_eigentextures(
        reference.eigentextures + rng.normal(0, 0.3, reference.eigentextures.shape)
    )
    shared = relative_error(reference, noisy)
    assert shared == pytest.approx(relative_error(reference, noisy, decompress=True), rel=1e-5)
    assert shared > 1.0
    # Different U (another sample's compression, another k).
    other = _random_btf(rng, k=6)
    assert relative_error(reference, other) == pytest.approx(
        relative_error(reference, other, decompress=True), rel=1e-5
    )
    assert relative_error(reference, reference) == pytest.approx(0.0, abs=1e-3)


def test_bad_inputs_are_named():
    with pytest.raises(InputError, match="shape"):
        compress(np.zeros((36, 10), np.float32), light_dirs=LIGHTS, view_dirs=VIEWS)
    btf = _random_btf(np.random.default_rng(4))
    with pytest.raises(InputError, match="light"):
        btf.image(99, 0)


# -------------------------------------------------------------------- constraints
def test_color_correction_against_hand_values_and_inverse():
    scan = np.array([[[0.51, 0.26, 0.81]]], np.float32)
    expected = [1.18 * 0.5**1.71, 1.14 * 0.25**1.83, 1.10 * 0.81**1.89]
    np.testing.assert_allclose(color_correct(scan)[0, 0], expected, rtol=1e-5)
    # Below the offset: clipped to 0, not NaN.
    assert color_correct(np.zeros((1, 1, 3), np.float32)).tolist() == [[[0.0, 0.0, 0.0]]]
    linear = np.random.default_rng(0).random((4, 5, 3), dtype=np.float32) * 0.8
    simulated = scanner_response(linear, bits=None)
    np.testing.assert_allclose(color_correct(simulated), linear, atol=1e-5)
    a = scanner_response(linear, noise=0.01, seed=7)
    b = scanner_response(linear, noise=0.01, seed=7)
    assert a.tobytes() == b.tobytes()


def test_histogram_alignment_factor_hand_computed():
    btf_images = [np.full((2, 2, 3), v, np.float32) for v in (0.2, 0.4, 0.2, 0.4)]
    scans = [np.full((2, 2, 3), v, np.float32) for v in (0.1, 0.1, 0.1, 0.1)]
    scans[1][..., 2] = 0.5  # blue mean over the four scans: (0.1 * 3 + 0.5) / 4 = 0.2
    factors = histogram_alignment_factors(btf_images, scans)
    np.testing.assert_allclose(factors, [0.3 / 0.1, 0.3 / 0.1, 0.3 / 0.2], rtol=1e-6)
    aligned = align_histograms(scans, factors)
    np.testing.assert_allclose(aligned[1][0, 0], [0.3, 0.3, 0.75], rtol=1e-6)


def _grey(values) -> np.ndarray:
    values = np.asarray(values, np.float32).reshape(1, -1, 1)
    return np.repeat(values, 3, axis=2)


def test_surface_descriptors_hand_computed():
    # Grey linear RGB has luminance Y = value, so L* = 116 Y^(1/3) - 16 (Y > 0.008856).
    def lstar(y):
        return 116 * np.cbrt(np.asarray(y, np.float64)) - 16

    i0, i90, i180, i270 = [0.5, 0.2, 0.3], [0.1, 0.4, 0.3], [0.2, 0.2, 0.6], [0.3, 0.1, 0.3]
    descriptors = surface_descriptors([_grey(i0), _grey(i90), _grey(i180), _grey(i270)])
    n1 = lstar(i0) - lstar(i180)
    n2 = lstar(i270) - lstar(i90)
    for got, raw in ((descriptors[0, :, 0], n1), (descriptors[0, :, 1], n2)):
        np.testing.assert_allclose(got, (raw - raw.mean()) / raw.std(), atol=2e-3)


def test_constraint_bands_layout_and_weights():
    rng = np.random.default_rng(5)
    images = [rng.random((3, 4, 3), dtype=np.float32) + 0.05 for _ in range(4)]
    bands = constraint_bands(images, ws=2.0, wc=10.0)
    assert bands.shape == (3, 4, 14)
    np.testing.assert_allclose(bands[..., :2], 2.0 * surface_descriptors(images), rtol=1e-6)
    for i, image in enumerate(images):
        np.testing.assert_allclose(bands[..., 2 + 3 * i : 5 + 3 * i], 10.0 * image, rtol=1e-6)


def test_neighbourhood_stacking_hand_computed():
    bands = np.arange(12, dtype=np.float32).reshape(3, 4, 1)
    stacked = stack_neighbourhood(bands, radius=1)
    assert stacked.shape == (3, 4, 9)
    # Interior texel (1, 1): its 3x3 neighbourhood, row-major.
    assert stacked[1, 1].tolist() == [0, 1, 2, 4, 5, 6, 8, 9, 10]
    # Corner (0, 0), reflected borders: rows (1, 0, 1), columns (1, 0, 1).
    assert stacked[0, 0].tolist() == [5, 4, 5, 1, 0, 1, 5, 4, 5]
    two = np.stack([bands[..., 0], -bands[..., 0]], axis=2)
    assert stack_neighbourhood(two, radius=1)[1, 1, :4].tolist() == [0, -0, 1, -1]


# ------------------------------------------------------------------ extrapolation
@pytest.fixture(scope="module")
def tiny_experiment():
    """A 64x64 leather ground truth (891 rows), its k=100 compression, a 24x24 sample."""
    from imagemap.btf.materials import make_material
    from imagemap.btf.rendering import default_sampling, render_btf_matrix

    lights, views = default_sampling()
    material = make_material("leather", size=64, seed=1)
    matrix = render_btf_matrix(material, lights, views)
    reference = compress(matrix, shape=(64, 64), light_dirs=lights, view_dirs=views, k=100)
    cols = (np.arange(20, 44)[:, None] * 64 + np.arange(20, 44)).ravel()
    sample = compress(matrix[:, cols], shape=(24, 24), light_dirs=lights, view_dirs=views, k=100)
    return reference, sample


def test_pixelwise_with_own_constraints_reproduces_the_sample(tiny_experiment):
    _, sample = tiny_experiment
    images = constraint_images(sample)
    for radius in (0, 1):
        params = PixelwiseParams(radius=radius, ws=1.0, wc=10.0, backend="kdtree")
        result, source = pixelwise(sample, images, images, params)
        np.testing.assert_array_equal(result.eigentextures, sample.eigentextures)
        assert relative_error(sample, result) == pytest.approx(0.0, abs=1e-3)
        yy, xx = np.mgrid[0:24, 0:24]
        assert np.array_equal(source[..., 0], yy) and np.array_equal(source[..., 1], xx)
        assert result.eigen_abrdfs is sample.eigen_abrdfs


def test_both_methods_beat_tiling_on_a_procedural_material(tiny_experiment):
    reference, sample = tiny_experiment
    truth = constraint_images(reference)
    scans = [
        scanner_response(im, gain=(1.2, 1.0, 0.9), noise=0.002, seed=i)
        for i, im in enumerate(truth)
    ]
    sample_images = constraint_images(sample)
    targets = prepare_scans(scans, sample_images)
    tiling_error = relative_error(reference, tile(sample, reference.shape))
    pw, _ = pixelwise(
        sample, sample_images, targets, PixelwiseParams(radius=0, ws=0, wc=1, backend="kdtree")
    )
    to_params = TextureOptimizationParams(radius=3, levels=2, stride=2, max_iterations=3)
    to, _ = texture_optimization(sample, sample_images, targets, to_params)
    pw_error, to_error = relative_error(reference, pw), relative_error(reference, to)
    assert pw.shape == to.shape == reference.shape
    assert pw_error < 0.7 * tiling_error, (pw_error, tiling_error)
    assert to_error < 0.8 * tiling_error, (to_error, tiling_error)


def test_prepared_scans_recover_the_linear_images(tiny_experiment):
    reference, sample = tiny_experiment
    truth = constraint_images(reference)
    scans = [scanner_response(im, gain=(1.3, 1.0, 0.8), bits=None) for im in truth]
    # Aligned to the truth's own images, colour correction + f_c undo gain and response.
    prepared = prepare_scans(scans, truth)
    for got, want in zip(prepared, truth, strict=True):
        np.testing.assert_allclose(got, np.clip(want, 0, None), atol=2e-3)


# ------------------------------------------------------------------------ UBO2014
def test_ubo2014_reader_on_a_file_written_in_the_dfmf_layout(tmp_path):
    from imagemap.btf.ubo2014 import read_ubo2014, write_ubo2014

    rng = np.random.default_rng(6)
    n_views, n_lights, height, width = len(VIEWS), len(LIGHTS), 5, 7
    ks = (4, 3, 2)  # fewer components for the chroma channels, as DFMF allows
    us = [np.linalg.qr(rng.normal(size=(n_views * n_lights, k)))[0] for k in ks]
    sigmas = [np.sort(rng.random(k))[::-1] + 1 for k in ks]
    sxvs = [rng.normal(size=(height, width, k)) for k in ks]
    path = write_ubo2014(
        tmp_path / "t.btf",
        eigen_abrdfs=us,
        singular_values=sigmas,
        eigentextures=sxvs,
        light_dirs=LIGHTS,
        view_dirs=VIEWS,
        color_model="YUV",
        channels=("Y", "U", "V"),
    )
    btf = read_ubo2014(path)
    assert btf.shape == (height, width) and btf.n_components == sum(ks)
    np.testing.assert_allclose(btf.light_dirs, LIGHTS, atol=1e-4)
    np.testing.assert_allclose(btf.eigen_abrdfs.T @ btf.eigen_abrdfs, np.eye(sum(ks)), atol=1e-5)
    light, view = 4, 1
    file_row = view * n_lights + light  # the file's rows: view-major, light fastest
    yuv = np.stack([sxvs[c] @ us[c][file_row] for c in range(3)], axis=2)
    yuv_to_rgb = np.array([[1, 0, 1.13983], [1, -0.39465, -0.5806], [1, 2.03211, 0]])
    np.testing.assert_allclose(btf.image(light, view), yuv @ yuv_to_rgb.T, atol=1e-4)
    np.testing.assert_allclose(btf.image(light, view, rgb=False), yuv, atol=1e-5)
    (tmp_path / "bad.btf").write_bytes(b"!FMF12FCER" + bytes(20))
    with pytest.raises(InputError, match="bad.btf"):
        read_ubo2014(tmp_path / "bad.btf")
    (tmp_path / "short.btf").write_bytes(path.read_bytes()[:300])
    with pytest.raises(InputError, match="truncated"):
        read_ubo2014(tmp_path / "short.btf")


# ---------------------------------------------------------------------------- CLI
def test_cli_extrapolate_and_render(tmp_path, tiny_experiment):
    from imagemap.cli import main
    from imagemap.io import read_image, write_image

    reference, sample = tiny_experiment
    sample.save(tmp_path / "sample.npz")
    scan_paths = []
    for i, image in enumerate(constraint_images(reference)):
        scan_paths.append(str(tmp_path / f"scan{i}.png"))
        write_image(scan_paths[-1], scanner_response(image, seed=i))  # 8-bit PNG
    out = tmp_path / "big.npz"
    argv = ["btf", "extrapolate", str(tmp_path / "sample.npz"), "--scans", *scan_paths]
    assert main([*argv, "-o", str(out), "--backend", "kdtree", "-q"]) == 0
    big = BTF.load(out)
    assert big.shape == (64, 64)
    assert relative_error(reference, big) < relative_error(reference, tile(sample, (64, 64)))
    png = tmp_path / "relit.png"
    assert main(["btf", "render", str(out), "--light", "60", "45", "-o", str(png)]) == 0
    assert read_image(png).shape == (64, 64, 3)
    assert main(["btf", "render", str(tmp_path / "missing.npz"), "-o", str(png)]) == 2


@pytest.mark.slow
@pytest.mark.ci_slow
def test_cli_experiment_writes_table2(tmp_path):
    from imagemap.cli import main

    argv = ["btf", "experiment", "--out", str(tmp_path), "--materials", "wood", "--size", "128"]
    assert main([*argv, "--search", "exact", "-q"]) == 0
    with open(tmp_path / "table2.csv") as handle:
        rows = list(csv.DictReader(handle))
    assert [r["method"] for r in rows][:2] == ["tiling", "pixelwise_R0_ws0_wc1"]
    errors = {r["method"]: float(r["rel_error_pct"]) for r in rows}
    assert errors["pixelwise_R0_ws0_wc1"] < errors["tiling"]
    assert errors["texture_optimization"] < errors["tiling"]
    assert (tmp_path / "wood_comparison.png").exists() and (tmp_path / "table2.md").exists()


# ------------------------------------------- issue 13: probes and material sources
def test_pixelwise_mean_of_k_nearest_texels(tiny_experiment):
    from scipy.spatial import cKDTree

    reference, sample = tiny_experiment
    sample_images = constraint_images(sample)
    targets = constraint_images(reference)
    params = PixelwiseParams(radius=0, ws=0.0, wc=1.0, backend="kdtree", neighbours=4)
    result, source = pixelwise(sample, sample_images, targets, params)
    a = constraint_bands(sample_images, ws=0.0, wc=1.0)[..., 2:].reshape(-1, 12)
    b = constraint_bands(targets, ws=0.0, wc=1.0)[..., 2:].reshape(-1, 12)
    index = cKDTree(a).query(b, k=4)[1]
    flat = sample.eigentextures.reshape(-1, sample.n_components)
    want = flat[index].mean(axis=1).reshape(result.eigentextures.shape)
    np.testing.assert_allclose(result.eigentextures, want, rtol=1e-5, atol=1e-6)
    assert np.array_equal(source[..., 0] * 24 + source[..., 1], index[:, 0].reshape(64, 64))
    with pytest.raises(InputError, match="neighbours"):
        pixelwise(sample, sample_images, targets, PixelwiseParams(neighbours=0))


def test_experiment_runs_on_a_material_source_it_is_given(tmp_path):
    from imagemap.btf.experiment import ExperimentParams, run_experiment

    lights = np.array([[0, 0], [22, 0], [22, 90], [22, 180], [22, 270], [60, 45]], np.float32)
    views = np.array([[0, 0], [45, 90]], np.float32)

    def stripes(size, seed):  # a material that the scans determine exactly
        rng = np.random.default_rng(seed)
        brdfs = rng.random((len(lights) * len(views) * 3, 4), dtype=np.float32)
        labels = (np.arange(size)[None, :] // 3 + np.arange(size)[:, None] // 5) % 4
        return brdfs[:, labels.ravel()], lights, views

    params = ExperimentParams(size=32, sample_size=16, k=8, scanner_noise=0.0)
    methods = ["tiling", "pixelwise_R0_ws0_wc1"]
    with pytest.raises(InputError, match="no source"):
        run_experiment(tmp_path, materials=["nothing"], params=params, methods=methods)
    rows = run_experiment(
        tmp_path,
        materials=["stripes"],
        params=params,
        sources={"stripes": stripes},
        methods=methods,
        extra_methods={},
    )
    errors = {r["method"]: r["rel_error_pct"] for r in rows}
    assert errors["pixelwise_R0_ws0_wc1"] < 0.5 * errors["tiling"], errors
    assert (tmp_path / "stripes_detail.png").exists() and (tmp_path / "table2.md").exists()
