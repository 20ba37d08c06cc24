"""data_gen: meshes, ray-cast depth against analytic values, maps, determinism, CLI."""

from __future__ import annotations

import json
import sys
import types

import numpy as np
import pytest
import trimesh

import data_gen
from data_gen.__main__ import main as data_gen_main
from data_gen.core import instance_rng
from data_gen.dataset import write_class
from data_gen.render import OrthographicView, cast_orthographic, ray_backend

SMALL = {"fish": (100, 75), "busts": (75, 100), "humans": (75, 100)}


@pytest.fixture(scope="module")
def instances() -> dict:
    return {
        name: data_gen.make_instance(name, 3, seed=5, size=SMALL[name], keep_mesh=True)
        for name in data_gen.CLASSES
    }


def test_ray_backend_follows_whether_embreex_imports(monkeypatch):
    monkeypatch.setitem(sys.modules, "embreex", None)  # "import embreex" raises ImportError
    assert ray_backend() == "rtree"
    monkeypatch.setitem(sys.modules, "embreex", types.ModuleType("embreex"))
    assert ray_backend() == "embreex"


def test_sphere_depth_is_analytic_and_aligned():
    # An off-centre sphere: a transposed or flipped image would put its peak elsewhere.
    center, radius = np.array([0.31, -0.21, 0.1]), 0.35  # on a pixel centre
    sphere = trimesh.creation.icosphere(subdivisions=5, radius=radius)
    sphere.apply_translation(center)
    view = OrthographicView(center=(0.0, 0.0), pixel_size=0.02, size=(80, 60))
    hits = cast_orthographic(sphere, view)
    xs, ys = view.pixel_centers()
    col = int(np.argmin(np.abs(xs - center[0])))
    row = int(np.argmin(np.abs(ys - center[1])))
    assert (row, col) == (40, 55)
    rows, cols = np.nonzero(hits.hit)
    assert rows.mean() == pytest.approx(row, abs=0.05) and cols.mean() == pytest.approx(
        col, abs=0.05
    )
    for d_row, d_col in [(0, 0), (5, 0), (0, -12), (-8, 9), (10, -10)]:
        r, c = row + d_row, col + d_col
        rho2 = (xs[c] - center[0]) ** 2 + (ys[r] - center[1]) ** 2
        expected = center[2] + np.sqrt(radius**2 - rho2)
        assert hits.z[r, c] == pytest.approx(expected, abs=2e-3)
    # Foreground is exactly the disc of pixel centres inside the silhouette (up to the
    # tessellation, which only shaves a thin rim).
    rho = np.hypot(xs[None, :] - center[0], ys[:, None] - center[1])
    assert np.array_equal(hits.hit[rho < radius - 0.01], np.ones((rho < radius - 0.01).sum()))
    assert not hits.hit[rho > radius].any()


def test_orthographic_cast_matches_trimesh_intersects_location(instances):
    """The vectorized broad phase gives exactly trimesh's own first hits."""
    mesh = instances["humans"].mesh
    view = OrthographicView(center=(0.0, 0.9), pixel_size=0.02, size=(75, 100))
    hits = cast_orthographic(mesh, view)
    xs, ys = view.pixel_centers()
    grid_x, grid_y = np.meshgrid(xs, ys)
    origins = np.stack([grid_x.ravel(), grid_y.ravel(), np.full(grid_x.size, 5.0)], axis=1)
    directions = np.tile([0.0, 0.0, -1.0], (len(origins), 1))
    locations, rays, faces = mesh.ray.intersects_location(origins, directions, multiple_hits=False)
    assert len(rays) > 500 and np.array_equal(np.sort(rays), hits.pixels)
    z = np.full(grid_x.size, np.nan)
    z[rays] = locations[:, 2]
    assert np.allclose(z[hits.pixels], hits.z.ravel()[hits.pixels], atol=1e-9)


def test_box_top_is_flat_and_edges_fall_between_pixels():
    box = trimesh.creation.box(extents=(0.8, 0.4, 0.3))
    box.apply_translation((0.2, 0.1, -0.05))
    view = OrthographicView(center=(0.0, 0.0), pixel_size=0.1, size=(16, 10))
    hits = cast_orthographic(box, view)
    xs, ys = view.pixel_centers()
    inside = ((np.abs(xs - 0.2) < 0.4)[None, :]) & ((np.abs(ys - 0.1) < 0.2)[:, None])
    assert np.array_equal(hits.hit, inside)
    assert np.allclose(hits.z[inside], 0.1, atol=1e-9)


@pytest.mark.parametrize("name", ["fish", "busts", "humans"])
def test_maps_shapes_ranges_background(instances, name):
    instance = instances[name]
    width, height = SMALL[name]
    assert instance.mesh.is_watertight and instance.mesh.is_winding_consistent
    assert instance.mesh.volume > 0
    assert instance.depth.shape == (height, width) and instance.depth.dtype == np.float32
    assert instance.image.shape == (height, width, 3) and instance.image.dtype == np.float32
    assert instance.labels.shape == (height, width) and instance.labels.dtype == np.uint8
    foreground = instance.labels > 0
    assert np.array_equal(foreground, instance.depth > 0)
    assert 0.1 < foreground.mean() < 0.7  # the object fills a good part of the frame
    assert instance.depth[foreground].min() >= 0.02 and instance.depth.max() <= 1.0
    assert np.all(instance.image[~foreground] == 0)
    assert instance.image.min() >= 0 and instance.image.max() <= 1
    parts = data_gen.CLASSES[name].parts
    assert set(np.unique(instance.labels)) <= set(range(len(parts) + 1))
    # Most parts show at this size (small ones like eyebrows or shoes may be hidden).
    assert len(np.unique(instance.labels)) - 1 >= len(parts) - 2
    # The object is not cut: no foreground on the left and right borders.
    assert not foreground[:, 0].any() and not foreground[:, -1].any()


def _distance_to_segment(colors: np.ndarray, first, second) -> np.ndarray:
    a, b = np.asarray(first, np.float32), np.asarray(second, np.float32)
    ab = b - a
    t = np.clip(((colors - a) @ ab) / max(float(ab @ ab), 1e-9), 0, 1)
    return np.linalg.norm(colors - (a + t[:, None] * ab), axis=1)


@pytest.mark.parametrize("name", ["fish", "busts", "humans"])
def test_labels_and_image_agree(instances, name):
    """Each part's pixels carry that part's colours, and fit them better than the others'."""
    instance = instances[name]
    palette = instance.params["appearance"]["palette"]
    parts = data_gen.CLASSES[name].parts
    for label, part in enumerate(parts, start=1):
        pixels = instance.image[instance.labels == label]
        if len(pixels) < 5:
            continue
        own = _distance_to_segment(pixels, *palette[part][:2])
        # The colours are blends of the part's two colours, times a grain of a few percent.
        assert np.mean(own < 0.12) > 0.85, part
        others = [
            np.median(_distance_to_segment(pixels, *palette[o][:2])) for o in parts if o != part
        ]
        assert np.median(own) < min(others), part


def test_determinism_and_count_independence(tmp_path):
    a = data_gen.make_instance("fish", 1, seed=9, size=(60, 45))
    b = data_gen.make_instance("fish", 1, seed=9, size=(60, 45))
    assert a.depth.tobytes() == b.depth.tobytes() and a.image.tobytes() == b.image.tobytes()
    assert a.params == b.params
    write_class(data_gen.CLASSES["fish"], tmp_path / "two", count=2, seed=9, size=(60, 45))
    write_class(data_gen.CLASSES["fish"], tmp_path / "three", count=3, seed=9, size=(60, 45))
    for suffix in ("_depth.png", "_image.png", "_labels.png", ".json"):
        one = (tmp_path / "two" / f"fish_001{suffix}").read_bytes()
        assert one == (tmp_path / "three" / f"fish_001{suffix}").read_bytes()


def test_different_seeds_and_indices_differ():
    base = data_gen.make_instance("busts", 0, seed=1, size=(45, 60))
    other_seed = data_gen.make_instance("busts", 0, seed=2, size=(45, 60))
    other_index = data_gen.make_instance("busts", 1, seed=1, size=(45, 60))
    for other in (other_seed, other_index):
        assert other.params["shape"] != base.params["shape"]
        assert np.abs(other.depth - base.depth).mean() > 0.01
        assert np.abs(other.image - base.image).mean() > 0.02
    # The instance stream depends on the class too.
    assert instance_rng("fish", 0, 1).random() != instance_rng("busts", 0, 1).random()


def test_cli_writes_a_readable_database_with_holdout(tmp_path, capsys):
    out = tmp_path / "fish"
    code = data_gen_main(
        ["fish", "--count", "3", "--holdout", "1", "--size", "64x48", "--out", str(out), "-q"]
    )
    assert code == 0
    names = sorted(p.name for p in out.glob("*_depth.png"))
    assert names == ["fish_000_depth.png", "fish_001_depth.png"]
    assert (out / "holdout" / "fish_002_image.png").exists()
    assert (out / "contact_sheet.png").exists()
    record = json.loads((out / "fish_001.json").read_text())
    assert record["class"] == "fish" and record["parts"]["1"] == "back"
    from imagemap.database import Database
    from imagemap.io import read_depth

    database = Database.from_directory(out)
    assert len(database) == 2
    depth = read_depth(out / "holdout" / "fish_002_depth.png")
    again = data_gen.make_instance("fish", 2, seed=0, size=(64, 48))
    assert np.allclose(depth, again.depth, atol=1 / 65535)
    assert data_gen_main(["fish", "--count", "2", "--holdout", "2", "--out", str(out)]) == 2
    assert "holdout" in capsys.readouterr().err


def test_unknown_class_is_refused():
    from imagemap.io import InputError

    with pytest.raises(InputError, match="class"):
        data_gen.make_instance("whales", 0)
