"""benchmarks/real_meshes.py on generated stand-in heads: rasterizer, database, baselines.

The benchmark's real heads (FFHQ-UV) are fetched by the user and never committed (their
textures derive from FFHQ, CC BY-NC-SA 4.0: docs/real_data.md); the tests run it on two
heads generated in one UV layout (``shared_heads`` in conftest.py, data_gen/heads.py).
"""

from __future__ import annotations

import importlib.util
import math
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "benchmarks" / "real_meshes.py"

pytestmark = pytest.mark.skipif(not SCRIPT.is_file(), reason="no benchmarks/ checkout")


@pytest.fixture(scope="module")
def rm():
    spec = importlib.util.spec_from_file_location("benchmark_real_meshes", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up while it loads
    try:
        spec.loader.exec_module(module)
    except BaseException:
        sys.modules.pop(spec.name, None)
        raise
    return module


def quad(rm, texture, size=1.0):
    """A square in the z = 0 plane facing +z, UVs (0, 0) bottom-left to (1, 1) top-right."""
    vertices = np.array([[-1.0, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]]) * size
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    uv = np.array([[0.0, 0], [1, 0], [1, 1], [0, 1]])
    return rm.TexturedArrays(vertices, faces, uv, np.asarray(texture, dtype=np.float32))


def test_rasterizer_draws_each_texture_quadrant_where_it_belongs(rm):
    texture = np.zeros((2, 2, 3), dtype=np.float32)
    texture[0, 0] = (1, 0, 0)  # top-left red
    texture[0, 1] = (0, 1, 0)  # top-right green
    texture[1, 0] = (0, 0, 1)  # bottom-left blue
    texture[1, 1] = (1, 1, 1)  # bottom-right white
    mesh = quad(rm, texture)
    camera = rm.look_at(0, 0, np.zeros(3), math.sqrt(2), size=64)
    image, mask = rm.render(mesh, camera)
    # Points well inside each quadrant, projected by the camera: the texel's colour exactly.
    points = np.array([[-0.75, 0.75, 0], [0.75, 0.75, 0], [-0.75, -0.75, 0], [0.75, -0.75, 0]])
    col, row, _ = camera.project(points)
    got = image[np.round(row).astype(int), np.round(col).astype(int)]
    assert got.tolist() == texture[[0, 0, 1, 1], [0, 1, 0, 1]].tolist()
    assert not mask[0, 0] and mask[32, 32]
    # The square's image: a square of side 2 f / d pixels (d = 3 radii from the centre).
    side = 2 * camera.focal / (rm.CAMERA_DISTANCE * math.sqrt(2))
    assert abs(mask.sum() - side**2) < 4 * side


def test_rasterizer_interpolates_with_perspective(rm):
    # A ramp texture (red = u) on a square turned 70 degrees from the camera: the colour
    # at the pixel of a surface point is that point's u. Screen-space (affine)
    # interpolation is off by up to 0.1 here; the perspective-correct one within a texel.
    ramp = np.zeros((1, 256, 3), dtype=np.float32)
    ramp[0, :, 0] = (np.arange(256) + 0.5) / 256
    mesh = quad(rm, ramp)
    camera = rm.look_at(70, 0, np.zeros(3), math.sqrt(2), size=256)
    image, _ = rm.render(mesh, camera)
    u = np.linspace(0.1, 0.9, 9)
    points = np.stack([2 * u - 1, np.zeros_like(u), np.zeros_like(u)], axis=1)
    col, row, _ = camera.project(points)
    got = image[np.round(row).astype(int), np.round(col).astype(int), 0]
    # One pixel of rounding moves u by at most the local footprint of a pixel.
    step = np.abs(np.gradient(u, col))
    assert np.all(np.abs(got - u) <= step + 1 / 256)
    affine = np.interp(col, [col[0], col[-1]], [u[0], u[-1]])
    assert np.abs(affine - u).max() > 0.05  # the case would catch an affine rasterizer


def test_nearer_surface_hides_the_farther_one(rm):
    # A white square 0.5 in front of a black one twice its size, in either drawing order.
    texture = np.zeros((1, 2, 3), dtype=np.float32)
    texture[0, 1] = 1.0  # u = 0: black, u = 1: white
    near = quad(rm, texture, size=0.5)
    far = quad(rm, texture)
    far.vertices = far.vertices - [0, 0, 0.5]
    near.uv[:, 0], far.uv[:, 0] = 1.0, 0.0
    camera = rm.look_at(0, 0, np.zeros(3), 1.5, size=64)
    corner = camera.project(np.array([[-0.8, 0.8, -0.5]]))
    for first, second in ((far, near), (near, far)):
        both = rm.TexturedArrays(
            np.concatenate([first.vertices, second.vertices]),
            np.concatenate([first.faces, second.faces + 4]),
            np.concatenate([first.uv, second.uv]),
            texture,
        )
        image, _ = rm.render(both, camera)
        assert image[32, 32].tolist() == [1.0, 1.0, 1.0]
        assert image[round(corner[1][0]), round(corner[0][0])].tolist() == [0.0, 0.0, 0.0]


def test_heads_are_a_database_with_one_uv_layout(rm, shared_heads):
    from imagemap.database import Database

    database = Database.from_directory(shared_heads)
    assert database.names == ["head_00", "head_01"]
    front = database["head_00"]
    # Measured: the head covers 0.24 of the front view, its mean colour 0.52.
    assert front.depth.shape == (150, 200) and (front.depth > 0).mean() > 0.2
    assert front.image[front.depth > 0].mean() > 0.2  # textured, not black
    meshes = [rm.TexturedArrays.load(p) for p in rm.mesh_files(shared_heads)]
    assert np.array_equal(meshes[0].uv, meshes[1].uv)
    assert np.array_equal(meshes[0].faces, meshes[1].faces)


def test_paste_of_an_object_onto_itself_has_no_error(rm, shared_heads):
    truth, other = (rm.TexturedArrays.load(p) for p in rm.mesh_files(shared_heads))
    centre, radius = truth.bounding_sphere()
    camera = rm.look_at(-40, 15, centre, radius, size=160)
    truth_image, mask = rm.render(truth, camera)
    self_paste, self_mask = rm.render(truth.with_texture(truth.texture), camera)
    assert np.array_equal(mask, self_mask) and mask.mean() > 0.1
    assert rm.image_errors(self_paste, truth_image, mask) == {"rgb": 0.0, "de00": 0.0,
                                                              "crisp": 1.0}  # fmt: skip
    other_paste, _ = rm.render(truth.with_texture(other.texture), camera)
    errors = rm.image_errors(other_paste, truth_image, mask)
    # Two people differ: measured 43.9 (|RGB|) and 16.4 (dE00) here, 41.8 texel by texel.
    assert errors["rgb"] > 3.0 and errors["de00"] > 1.0
    assert rm.uv_errors(truth.texture, truth.texture, truth.uv, truth.faces, 64)["rgb"] == 0.0
    assert rm.uv_errors(other.texture, truth.texture, truth.uv, truth.faces, 64)["rgb"] > 3.0


def test_used_texels_exclude_the_atlas_padding(rm, shared_heads):
    truth = rm.TexturedArrays.load(rm.mesh_files(shared_heads)[0])
    used = rm.used_texels(truth.uv, truth.faces, 64)
    assert 0.3 < used.mean() < 0.95  # measured 0.86
    # Paint only unused texels: the UV measure does not see it.
    painted = rm.texture_at(truth.texture, 64).copy()
    painted[~used] = 1.0 - painted[~used]
    assert rm.uv_errors(painted, truth.texture, truth.uv, truth.faces, 64)["rgb"] == 0.0
    painted[used] = 1.0 - painted[used]
    assert rm.uv_errors(painted, truth.texture, truth.uv, truth.faces, 64)["rgb"] > 50.0


def test_first_choice_is_the_only_other_example(rm, shared_heads):
    assert rm.first_choice("head_00", shared_heads) == "head_01"


def test_bad_folders_stop_before_any_synthesis(rm, shared_heads, tmp_path):
    from imagemap.io import InputError

    with pytest.raises(InputError, match="not a folder"):
        rm.evaluate(tmp_path / "missing", tmp_path)
    (tmp_path / "one").mkdir()
    (tmp_path / "one" / "a.glb").write_bytes((shared_heads / "head_00.glb").read_bytes())
    with pytest.raises(InputError, match="at least two"):
        rm.evaluate(tmp_path / "one", tmp_path)
    with pytest.raises(InputError, match="no mesh named nobody"):
        rm.evaluate(shared_heads, tmp_path, only=["nobody"])
    assert rm.main(["run", str(tmp_path / "one"), "--out", str(tmp_path / "out")]) == 2
    assert not list((tmp_path / "out").glob("*.glb"))


@pytest.mark.slow
def test_leave_one_out_on_the_heads(rm, shared_heads, tmp_path):
    report = rm.evaluate(shared_heads, tmp_path, views="front,left,right", size=96)
    assert len(report["rows"]) == 2 * len(rm.EVAL_VIEWS) and report["shared_uv"]
    for row in report["rows"]:
        assert row["mask_iou"] > 0.98  # the result keeps the query's geometry
        assert row["first_choice"] != row["object"]
    summary = rm.summary(report)
    assert 0 <= summary["ours_beats_paste"] <= summary["object_views"]
    assert "| **mean** |" in rm.table(report)
