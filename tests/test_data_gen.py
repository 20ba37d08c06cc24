"""data_gen: meshes, ray-cast depth against analytic values, maps, determinism, CLI."""

from __future__ import annotations

import json
import sys
import types

import numpy as np
import pytest
import trimesh
from scipy import ndimage

import data_gen
from data_gen.__main__ import main as data_gen_main
from data_gen.core import instance_rng
from data_gen.dataset import write_class
from data_gen.render import OrthographicView, cast_orthographic, ray_backend

# Shells at their default size: their grooves are 3-4 px wide there (a tortoise costs
# what it costs at any size: the ray cast's time goes with its 60,000 faces).
SMALL = {"fish": (100, 75), "busts": (75, 100), "humans": (75, 100), "shells": (200, 150)}


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


@pytest.mark.parametrize("name", ["fish", "busts", "humans", "shells"])
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


@pytest.mark.parametrize("name", ["fish", "busts", "humans", "shells"])
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


# -- shells: plates between grooves carved into the relief and painted dark ------------------


@pytest.fixture(scope="module")
def shells(instances) -> list:
    """Two tortoises at the default size: instances 3 and 4 of seed 5."""
    return [instances["shells"], data_gen.make_instance("shells", 4, seed=5)]


def _part(name: str) -> int:
    return data_gen.CLASSES["shells"].parts.index(name) + 1


def test_shells_are_the_same_bytes_for_a_seed(instances):
    again = data_gen.make_instance("shells", 3, seed=5, size=SMALL["shells"])
    first = instances["shells"]
    for kind in ("depth", "image", "labels"):
        assert getattr(again, kind).tobytes() == getattr(first, kind).tobytes(), kind
    assert again.params == first.params


def test_shells_labels_hold_plates_between_grooves(shells):
    for shell in shells:
        labels = shell.labels
        assert {_part(p) for p in ("plate", "groove", "rim", "skin")} <= set(np.unique(labels))
        carapace = np.isin(labels, [_part("plate"), _part("groove")])
        share = (labels == _part("groove")).sum() / carapace.sum()
        assert 0.08 < share < 0.4, share
        # The grooves cut the dome into plates: as many pieces as seeds, about (a seed's
        # plate may be hidden by its neighbours' or cut in two by the view's edge).
        pieces = ndimage.label(labels == _part("plate"))[1]
        seeds = len(shell.params["shape"]["plate_seeds"])
        assert seeds >= 5 and abs(pieces - seeds) <= 2, (pieces, seeds)
        # The grooves are painted dark: darker than the plates almost everywhere.
        luma = shell.image @ np.array([0.299, 0.587, 0.114], dtype=np.float32)
        assert np.percentile(luma[labels == _part("groove")], 90) < np.median(
            luma[labels == _part("plate")]
        )


def test_shells_grooves_are_lower_than_their_surroundings(shells):
    """Relief follows paint: a groove pixel lies below the plates around it, and the
    carapace's pixels below their plate surroundings are groove pixels."""
    for shell in shells:
        depth, labels = shell.depth.astype(np.float64), shell.labels
        plate = labels == _part("plate")
        inner = ndimage.binary_erosion(labels > 0, iterations=4)
        # Mean depth of the plate pixels within 3 px (a 7 x 7 window).
        window = np.ones((7, 7))
        count = ndimage.convolve(plate.astype(np.float64), window, mode="constant")
        total = ndimage.convolve(np.where(plate, depth, 0.0), window, mode="constant")
        surroundings = np.where(count > 0, total / np.maximum(count, 1), np.nan)
        below = surroundings - depth
        groove = (labels == _part("groove")) & inner & (count >= 8)
        assert groove.sum() > 200
        # Measured on instances 3 and 4 of seed 5: 99.4-99.7 % below, by 0.020-0.021
        # (median) in depth units, of grooves 0.026 deep at their middle (0.025-0.041 in
        # the class).
        assert np.mean(below[groove] > 0) > 0.9
        assert np.median(below[groove]) > 0.008
        # Conversely, the carapace pixels lying well below their plate surroundings are
        # in a groove or within a pixel of one (measured: 99 %), away from the rim, where
        # the dome falls steeply and a plate's edge lies below the plate above it.
        near_groove = ndimage.binary_dilation(labels == _part("groove"))
        away = ndimage.distance_transform_edt(labels != _part("rim")) > 4
        carapace = np.isin(labels, [_part("plate"), _part("groove")])
        low = carapace & inner & away & (count >= 8) & (below > 0.01)
        assert low.sum() > 500 and np.mean(near_groove[low]) > 0.95


def test_shells_differ_in_plate_layout(shells):
    first, second = (s.params["shape"] for s in shells)
    assert first["plate_seeds"] != second["plate_seeds"]
    grooves = [s.labels == _part("groove") for s in shells]
    overlap = (grooves[0] & grooves[1]).sum() / (grooves[0] | grooves[1]).sum()
    assert overlap < 0.35, overlap


def test_shells_mesh_atlas_is_the_rendered_map(instances):
    """--meshes: the class's own atlas (no xatlas charting of the carapace) rendered from
    the front gives the rendered image-map."""
    import trimesh

    from data_gen.core import _view_window
    from data_gen.dataset import instance_mesh
    from imagemap.scene.views import surface_colours

    shells = data_gen.CLASSES["shells"]
    instance = instances["shells"]  # instance 3 of seed 5
    mesh = instance_mesh(shells, 3, seed=5, texture_size=256)
    hits = cast_orthographic(mesh, _view_window(shells, SMALL["shells"], instance.params["view"]))
    # (The view as the record keeps it, to 6 decimals.)
    assert np.mean(hits.hit != (instance.labels > 0)) < 1e-3
    barycentric = trimesh.triangles.points_to_barycentric(mesh.triangles[hits.faces], hits.points)
    colours = surface_colours(mesh, hits.faces, barycentric)
    assert np.median(np.abs(colours - instance.image.reshape(-1, 3)[hits.pixels])) < 0.03


def test_unknown_class_is_refused():
    from imagemap.io import InputError

    with pytest.raises(InputError, match="class"):
        data_gen.make_instance("whales", 0)


# -- heads in one UV layout (data_gen.heads: the stand-in for the FFHQ-UV heads) -------------


def test_heads_share_one_layout_and_are_different_people():
    from data_gen.heads import shared_layout_heads
    from imagemap.scene.bake import covered_texels
    from imagemap.scene.views import texture_image

    for seed in (0, 1, 2):
        heads = shared_layout_heads(3, seed=seed)
        first = heads[0]
        used = covered_texels(first.visual.uv, first.faces, 128)
        for other in heads[1:]:
            assert np.array_equal(other.faces, first.faces)
            assert np.array_equal(other.visual.uv, first.visual.uv)
            # Other shapes (a vertex moves by 0.07-0.24 units on a 3-unit head: heads 1
            # and 2 against head 0, seeds 0-11) ...
            assert np.abs(other.vertices - first.vertices).max() > 0.05
            # ... and other people: the textures differ by 17.5-102 of 255 (the same
            # heads; the skin tones of any two of the first three heads are 0.24 of the
            # ramp apart at least, of the first two 0.38).
            difference = np.abs(texture_image(other)[used] - texture_image(first)[used]).mean()
            assert difference * 255 > 10, (seed, difference * 255)


def test_heads_are_one_surface_cut_at_the_back():
    from data_gen.heads import shared_layout_heads

    head = shared_layout_heads(1, seed=5)[0]
    uv, vertices = head.visual.uv, head.vertices
    # Welded by position, the surface's only border is the neck's open end (48 edges, one
    # loop): the layout's slit along the back of the head and the crown's fan are cuts of
    # the UVs, not holes.
    welded = trimesh.Trimesh(vertices, head.faces, process=False)
    welded.merge_vertices(merge_tex=True, merge_norm=True)
    edges = welded.edges_sorted
    border = edges[trimesh.grouping.group_rows(edges, require_count=1)]
    assert len(border) == 48 and len(np.unique(border)) == 48
    assert np.ptp(welded.vertices[np.unique(border), 1]) < 1e-9  # a horizontal cut
    assert welded.vertices[np.unique(border), 1].max() < vertices[:, 1].min() + 1e-9
    # The chart's left and right borders are the same points, at the back (z < 0).
    left = np.isclose(uv[:, 0], uv[:, 0].min())
    right = np.isclose(uv[:, 0], uv[:, 0].max())
    order_l, order_r = np.argsort(uv[left, 1]), np.argsort(uv[right, 1])
    np.testing.assert_array_equal(vertices[left][order_l], vertices[right][order_r])
    assert (vertices[left][:, 2] < 0).all()
    # A head: taller than deep, deeper than wide; the nose's tip the frontmost point, on
    # the midline and below the middle of the head.
    extent = np.ptp(vertices, axis=0)
    assert extent[1] > extent[2] > extent[0]
    tip = vertices[np.argmax(vertices[:, 2])]
    assert abs(tip[0]) < 0.02 * extent[0] and tip[1] < np.median(vertices[:, 1])


def test_heads_are_the_same_bytes_for_a_seed(tmp_path):
    from data_gen.heads import write_shared_layout_heads

    first = write_shared_layout_heads(tmp_path / "a", count=2, seed=3)
    again = write_shared_layout_heads(tmp_path / "b", count=3, seed=3)
    other = write_shared_layout_heads(tmp_path / "c", count=2, seed=4)
    assert [p.name for p in first] == ["head_00.glb", "head_01.glb"]
    # Head i does not depend on the count (the third head of ``again`` is left over).
    for a, b, c in zip(first, again[:2], other, strict=True):
        assert a.read_bytes() == b.read_bytes() and a.read_bytes() != c.read_bytes()


# -- the grey sphere under 12 lights (data_gen.photometric: the stand-in for psmImages') ----


def test_grey_sphere_files_hold_the_generated_set(tmp_path):
    from data_gen.photometric import grey_sphere, light_directions, write_grey_sphere
    from imagemap.btf.photometric_io import read_image_stack, read_lights, read_mask

    paths = write_grey_sphere(tmp_path / "a", seed=0)
    again = write_grey_sphere(tmp_path / "b", seed=0)
    assert [p.read_bytes() for p in paths] == [p.read_bytes() for p in again]
    sphere = grey_sphere(seed=0)
    images = read_image_stack(paths[:12])[..., 0]
    np.testing.assert_array_equal(images, sphere.images)
    np.testing.assert_array_equal(read_mask(paths[12], images.shape[1:]), sphere.mask)
    lights = read_lights(paths[13])  # the count line, then one vector per line
    np.testing.assert_allclose(lights, light_directions(), atol=1e-6)
    # Within 40 degrees of the view axis, all around it.
    assert np.degrees(np.arccos(lights[:, 2])).max() < 40.01  # (6 decimals in the file)
    assert np.ptp(np.degrees(np.arctan2(lights[:, 1], lights[:, 0]))) > 300


def test_grey_sphere_has_what_real_captures_have():
    from data_gen.photometric import grey_sphere

    sphere = grey_sphere(seed=0)
    images, lights, mask, normals = sphere.images, sphere.lights, sphere.mask, sphere.normals
    # The mask is the sphere's disc: its area that of a 27 px radius (2,290 px).
    assert abs(mask.sum() - np.pi * 27.0**2) < 30
    # A highlight at the half vector of each light (the frame is x right, y up): the
    # brightest pixel of each image has the normal of light + view (measured: within 2.0
    # degrees; with y flipped 4.6-39).
    half = lights + [0.0, 0.0, 1.0]
    half /= np.linalg.norm(half, axis=1, keepdims=True)
    for image, h in zip(images, half, strict=True):
        smooth = ndimage.uniform_filter(np.where(mask, image, 0.0), 3)
        peak = np.unravel_index(np.argmax(smooth), smooth.shape)
        assert np.degrees(np.arccos(np.clip(normals[peak] @ h, -1, 1))) < 3.0
    # A few clipped highlights: some images reach full scale, on a few pixels only
    # (measured: 5 of 12 images, 2-5 pixels each).
    clipped = (images >= 1.0).sum(axis=(1, 2))
    assert 2 <= (clipped > 0).sum() <= 8 and clipped.max() <= 10
    # Attached shadows: where a light grazes behind the surface (n.l < -0.2) only the
    # ambient and bounced light remain, a few levels above black, not 0 (median 3).
    shade = np.einsum("hwc,nc->nhw", normals, lights)
    dark = images[(shade < -0.2) & mask[None]] * 255
    assert dark.size > 100 and 0 < np.median(dark) < 8
    # 8-bit levels, and noise: on the lit sphere away from the highlights, a pixel's
    # difference from its 3 x 3 mean is 2.6 levels (RMS; the shading is smooth there).
    assert np.array_equal(images * 255, np.round(images * 255))
    residual = images - ndimage.uniform_filter(images, (1, 3, 3))
    inner = ndimage.binary_erosion(mask, iterations=3)
    glossy = np.einsum("hwc,nc->nhw", normals, half) > 0.97
    lit = (shade > 0.5) & inner[None] & ~glossy
    noise = np.std(residual[lit]) * 255
    assert 1.5 < noise < 4.0, noise
