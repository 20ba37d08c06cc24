"""Meshes: views, rendering alignment, projection and baked textures, export, examples."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from imagemap.database import Database
from imagemap.io import InputError, read_image, write_image
from imagemap.scene import (
    FRONT,
    MeshExample,
    View,
    bake_views,
    check_textured,
    export_textured,
    load_mesh,
    parse_view,
    parse_views,
    project_texture,
    rasterize_uv,
    render_colours,
    render_mesh,
    render_textured,
    sample_image,
    textured_mesh,
)

RED, BLUE = np.array([0.9, 0.1, 0.1]), np.array([0.1, 0.2, 0.9])


#: The imagemap module a mesh example's render runs that does not decide its values: the
#: cache file's writing (io; measured: the only one besides the render key's sources).
NOT_RENDERING = {"io.py"}


def stepped_block() -> trimesh.Trimesh:
    """A 2 x 1 x 0.5 slab with a 0.4-wide tower (z up to 0.55) at x, y = (0.6, 0.2)."""
    slab = trimesh.creation.box(extents=(2.0, 1.0, 0.5))
    tower = trimesh.creation.box(extents=(0.4, 0.4, 0.8))
    tower.apply_translation((0.6, 0.2, 0.15))
    return trimesh.util.concatenate([slab, tower])


def pixel_of(render, x: float, y: float, z: float = 0.0) -> tuple[int, int]:
    col, row, _ = render.to_pixels(np.array([[x, y, z]]))
    return int(round(row[0])), int(round(col[0]))


def test_views_parse_names_pairs_and_reject_garbage():
    assert parse_views("front,back") == [View(0, 0), View(180, 0)]
    assert parse_views("0,0;90,-20") == [View(0, 0), View(90, -20)]
    assert parse_views("left 30,10") == [View(-90, 0), View(30, 10)]
    assert parse_view(None) == FRONT
    with pytest.raises(InputError, match="expected AZ,EL"):
        parse_views("front,30")
    with pytest.raises(InputError, match="elevation"):
        parse_view("0,120")
    with pytest.raises(InputError, match="one view"):
        parse_view("front,back")
    # The rotation takes the view direction to +z (the camera side).
    for view in (View(30, 20), View(-120, -45), View(0, 90)):
        np.testing.assert_allclose(view.rotation() @ view.direction, [0, 0, 1], atol=1e-12)


def test_render_front_alignment_known_depth_at_known_pixels():
    mesh = stepped_block()
    render = render_mesh(mesh, "front", size=(80, 60))
    # Framing: x extent 2 fills 84 % of 80 px; z extent 0.8 (-0.25..0.55), scale = 2.
    assert render.pixel_size == pytest.approx(2.0 / (80 * 0.84))
    slab = render.depth[pixel_of(render, -0.6, -0.2)]
    tower = render.depth[pixel_of(render, 0.6, 0.2)]
    assert slab == pytest.approx(0.1 + 0.9 * (0.25 + 0.25) / 2.0, abs=1e-5)
    assert tower == pytest.approx(0.1 + 0.9 * (0.55 + 0.25) / 2.0, abs=1e-5)
    # The tower is at the top right of the picture (x right, y up, row 0 at the top).
    rows, cols = np.nonzero(render.depth > slab + 0.01)
    assert cols.min() > 40 and rows.max() < 30
    assert not render.mask[0, 0] and render.depth[0, 0] == 0
    # The slab covers exactly the pixel centres inside x in [-1, 1], y in [-0.5, 0.5].
    centre_x = render.center[0] + (np.arange(80) + 0.5 - 40) * render.pixel_size
    np.testing.assert_array_equal(render.mask[30], np.abs(centre_x) < 1.0)
    # Faces and barycentrics reproduce the hit points.
    pixels = np.flatnonzero(render.mask)
    corners = mesh.triangles[render.face.flat[pixels]]
    points = np.einsum("nk,nkc->nc", render.barycentric.reshape(-1, 3)[pixels], corners)
    col, row, z = render.to_pixels(points)
    np.testing.assert_allclose(col, pixels % 80, atol=1e-4)
    np.testing.assert_allclose(row, pixels // 80, atol=1e-4)
    np.testing.assert_allclose(z, render.z.flat[pixels], atol=1e-6)


def test_render_side_view_sees_the_tower_side():
    mesh = stepped_block()
    render = render_mesh(mesh, "right", size=(60, 60))
    # From +x the picture's x is world -z: the tower (world z up to 0.55) is on the left.
    near = render.to_pixels(np.array([[1.0, 0.2, 0.5]]))
    assert near[0][0] < 30
    # The nearest surface from +x is the slab's x = 1 face and the tower's x = 0.8 face.
    assert render.depth.max() == pytest.approx(1.0, abs=1e-5)


def test_load_mesh_rejects_bad_files_naming_them(tmp_path):
    with pytest.raises(InputError, match="missing.glb: mesh file not found"):
        load_mesh(tmp_path / "missing.glb")
    text = tmp_path / "notes.txt"
    text.write_text("hello")
    with pytest.raises(InputError, match="notes.txt: unsupported mesh format"):
        load_mesh(text)
    garbage = tmp_path / "garbage.glb"
    garbage.write_bytes(b"\x00not a mesh at all")
    with pytest.raises(InputError, match="garbage.glb"):
        load_mesh(garbage)


def half_coloured_image(render) -> np.ndarray:
    """Red where the hit is at world x > 0, blue elsewhere (background black)."""
    height, width = render.depth.shape
    xs = render.center[0] + (np.arange(width) + 0.5 - width / 2) * render.pixel_size
    image = np.where((xs > 0)[None, :, None], RED, BLUE) * np.ones((height, 1, 1))
    image[~render.mask] = 0.0
    return image.astype(np.float32)


def test_projection_texture_round_trips_through_glb_and_a_new_view(tmp_path):
    sphere = trimesh.creation.icosphere(subdivisions=4)
    render = render_mesh(sphere, "front", size=(64, 48))
    image = half_coloured_image(render)
    textured = project_texture(sphere, render, image)
    path = export_textured(textured, tmp_path / "sphere.glb")[0]
    assert check_textured(path)
    loaded = load_mesh(path)
    assert isinstance(loaded.visual, trimesh.visual.TextureVisuals)
    # From the same view the texture reproduces the picture (away from the seam x = 0).
    again = render_colours(loaded, render_mesh(loaded, "front", size=(64, 48)))
    inner = render.mask & (np.abs(np.arange(64) - 31.5) > 2)[None, :]
    np.testing.assert_allclose(again[inner], image[inner], atol=2 / 255)
    # From a new view (az 40, el 25): world x > 0 red, x < 0 blue, no background black.
    new = render_mesh(loaded, "40,25", size=(64, 48))
    colours = render_colours(loaded, new)
    pixels = np.flatnonzero(new.mask)
    corners = loaded.triangles[new.face.flat[pixels]]
    points = np.einsum("nk,nkc->nc", new.barycentric.reshape(-1, 3)[pixels], corners)
    rgb = colours.reshape(-1, 3)[pixels]
    clear = np.abs(points[:, 0]) > 0.1
    expected = np.where((points[:, 0] > 0)[:, None], RED, BLUE)
    assert np.abs(rgb[clear] - expected[clear]).max() < 0.05
    assert rgb.sum(axis=1).min() > 0.5
    picture = render_textured(loaded, "40,25", size=(64, 48))
    write_image(tmp_path / "new_view.png", picture)
    assert read_image(tmp_path / "new_view.png").shape == (48, 64, 3)


def test_hidden_faces_take_the_visible_texel_in_front_of_them():
    sphere = trimesh.creation.icosphere(subdivisions=3)
    render = render_mesh(sphere, "front", size=(48, 48))
    textured = project_texture(sphere, render, half_coloured_image(render))
    back = render_mesh(textured, "back", size=(48, 48))
    colours = render_colours(textured, back)
    # Seen from behind, world x > 0 is on the picture's left: it is red there too.
    row = colours[24][back.mask[24]]
    assert np.allclose(row[2], RED, atol=0.05) and np.allclose(row[-3], BLUE, atol=0.05)
    assert colours[back.mask].sum(axis=1).min() > 0.5  # no black: never background


def test_rasterize_uv_covers_a_triangle_exactly():
    uv = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    texel, face, bary = rasterize_uv(uv, np.array([[0, 1, 2]]), 8)
    # Texel (i, j) centre ((j + .5) / 8, 1 - (i + .5) / 8) is inside when u + v <= 1.
    rows, cols = np.divmod(texel, 8)
    u, v = (cols + 0.5) / 8, 1 - (rows + 0.5) / 8
    assert np.all(u + v <= 1 + 1e-9) and len(texel) == 36
    np.testing.assert_allclose(bary @ uv, np.stack([u, v], axis=1), atol=1e-9)
    assert np.all(face == 0)


def test_bake_blends_views_by_how_squarely_they_see():
    sphere = trimesh.creation.icosphere(subdivisions=3)
    views = [View(0, 0), View(180, 0)]
    renders = [render_mesh(sphere, v, size=(48, 48)) for v in views]
    images = [
        np.where(r.mask[..., None], colour, 0).astype(np.float32)
        for r, colour in zip(renders, (RED, BLUE), strict=True)
    ]
    baked = bake_views(sphere, renders, images, texture_size=128)
    assert baked.visual.uv is not None and len(baked.vertices) >= len(sphere.vertices)
    for view, colour in ((View(0, 0), RED), (View(180, 0), BLUE)):
        render = render_mesh(baked, view, size=(48, 48))
        seen = render_colours(baked, render)[render.mask]
        centre = render_colours(baked, render)[24, 24]
        np.testing.assert_allclose(centre, colour, atol=0.03)
        assert seen.sum(axis=1).min() > 0.5
    # Side on, the two views meet: a blend from red to blue, no black seam.
    side = render_mesh(baked, "right", size=(48, 48))
    middle = render_colours(baked, side)[24][side.mask[24]]
    assert middle[:, 0].max() > 0.7 and middle[:, 2].max() > 0.7
    assert middle.sum(axis=1).min() > 0.5


def test_obj_export_writes_its_own_texture_and_loads_back(tmp_path):
    sphere = trimesh.creation.icosphere(subdivisions=2)
    render = render_mesh(sphere, "front", size=(32, 32))
    for name in ("a", "b"):
        textured = project_texture(sphere, render, half_coloured_image(render))
        written = export_textured(textured, tmp_path / f"{name}.obj")
        assert [p.name for p in written] == [f"{name}.png", f"{name}.mtl", f"{name}.obj"]
    assert "map_Kd a.png" in (tmp_path / "a.mtl").read_text()
    assert check_textured(tmp_path / "a.obj") and check_textured(tmp_path / "b.obj")
    with pytest.raises(InputError, match="glb or .obj"):
        export_textured(textured, tmp_path / "x.ply")


def test_sample_image_is_exact_at_texel_centres():
    image = np.random.default_rng(0).random((5, 7, 3)).astype(np.float32)
    rows, cols = np.mgrid[0:5, 0:7]
    uv = np.stack([(cols.ravel() + 0.5) / 7, 1 - (rows.ravel() + 0.5) / 5], axis=1)
    np.testing.assert_allclose(sample_image(image, uv), image.reshape(-1, 3), atol=1e-6)


def coloured_sphere(path, colour) -> None:
    sphere = trimesh.creation.icosphere(subdivisions=3)
    uv = np.zeros((len(sphere.vertices), 2)) + 0.5
    texture = np.ones((4, 4, 3), np.float32) * np.asarray(colour, np.float32)
    textured_mesh(sphere.vertices * [1.5, 1.0, 0.8], sphere.faces, uv, texture).export(path)


def test_meshes_in_a_database_are_rendered_once_and_cached(tmp_path, monkeypatch):
    db_dir = tmp_path / "db"
    db_dir.mkdir()
    coloured_sphere(db_dir / "ball.glb", RED)
    cache = tmp_path / "cache"
    monkeypatch.setenv("IMAGEMAP_CACHE", str(cache))
    database = Database.from_directory(db_dir, view="front", size=(40, 30))
    example = database["ball"]
    assert isinstance(example, MeshExample)
    truth = render_mesh(load_mesh(db_dir / "ball.glb"), "front", size=(40, 30))
    np.testing.assert_array_equal(example.depth, truth.depth)
    np.testing.assert_allclose(
        example.image[truth.mask], np.broadcast_to(RED, (truth.mask.sum(), 3)), atol=3 / 255
    )
    cached = list((cache / "meshes").glob("ball-*.npz"))
    assert len(cached) == 1
    # A second open reads the cache: no mesh is loaded.
    monkeypatch.setattr(
        "imagemap.scene.examples.load_mesh", lambda path: pytest.fail("rendered again")
    )
    again = Database.from_directory(db_dir, view="front", size=(40, 30))["ball"]
    np.testing.assert_array_equal(again.depth, example.depth)
    monkeypatch.undo()
    monkeypatch.setenv("IMAGEMAP_CACHE", str(cache))
    # Another view or another file content is another key.
    side = Database.from_directory(db_dir, view="30,0", size=(40, 30))["ball"]
    assert side.depth.shape == (30, 40)
    coloured_sphere(db_dir / "ball.glb", BLUE)
    assert (
        Database.from_directory(db_dir, view="front", size=(40, 30))["ball"].image[15, 20, 2] > 0.8
    )
    assert len(list((cache / "meshes").glob("ball-*.npz"))) == 3


def test_an_edit_to_the_rendering_code_renders_the_examples_anew(tmp_path, monkeypatch):
    """The render cache's key holds a digest of the rendering modules' source: the same
    source (a copy) gives the same cache file, an edit to one of them another."""
    import shutil

    import imagemap.scene.examples as examples_module
    from imagemap.cache import source_digest

    coloured_sphere(tmp_path / "ball.glb", RED)
    example = MeshExample("ball", tmp_path / "ball.glb", size=(40, 30), cache_dir=tmp_path)
    installed = example.cache_path()
    copy = tmp_path / "code"
    for name in examples_module.RENDER_SOURCES:
        (copy / name).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(examples_module._PACKAGE / name, copy / name)
    monkeypatch.setattr(examples_module, "_PACKAGE", copy)
    assert example.cache_path() == installed
    with open(copy / "scene" / "views.py", "a") as views:
        views.write("# an edit\n")
    source_digest.cache_clear()  # as a new process: the digest is read once per process
    assert example.cache_path() != installed


def test_the_render_key_holds_every_module_a_render_runs(tmp_path):
    """Every imagemap module whose code runs while a mesh example with a normal map is
    rendered is in the render key's sources, or only writes the cache file
    (:data:`NOT_RENDERING`): a module added to the render must join the key."""
    import sys
    from pathlib import Path

    import imagemap
    from imagemap.scene.examples import RENDER_SOURCES

    sphere = trimesh.creation.icosphere(subdivisions=2)
    uv = sphere.vertices[:, :2] * 0.4 + 0.5
    normal = np.zeros((8, 8, 3), np.float32) + [0.6, 0.5, 0.9]
    mesh = textured_mesh(
        sphere.vertices, sphere.faces, uv, np.full((8, 8, 3), 0.5, np.float32),
        maps={"normal": normal},
    )  # fmt: skip
    mesh.export(tmp_path / "ball.glb")
    example = MeshExample("ball", tmp_path / "ball.glb", size=(24, 18), cache_dir=tmp_path)
    package = Path(imagemap.__file__).resolve().parent
    ran: set[str] = set()

    def note(frame, event, arg):
        if event == "call":
            ran.add(frame.f_code.co_filename)

    sys.setprofile(note)
    try:
        maps = example.rendered_maps()
    finally:
        sys.setprofile(None)
    assert "normal" in maps
    ours = {
        Path(f).resolve().relative_to(package).as_posix()
        for f in ran
        if Path(f).resolve().is_relative_to(package)
    }
    assert {"scene/raycast.py", "tangents.py"} <= ours  # the render and the normal map ran
    assert ours - set(RENDER_SOURCES) <= NOT_RENDERING


def test_mesh_and_picture_with_one_name_is_a_problem(tmp_path):
    coloured_sphere(tmp_path / "obj.glb", RED)
    write_image(tmp_path / "obj_depth.png", np.pad(np.ones((10, 10)), 2) * 0.5, bits=16)
    write_image(tmp_path / "obj_image.png", np.zeros((14, 14, 3)))
    with pytest.raises(InputError, match="obj.glb: an example named 'obj' exists already"):
        Database.from_directory(tmp_path)


def test_mesh_without_colours_cannot_be_an_example(tmp_path, monkeypatch):
    monkeypatch.setenv("IMAGEMAP_CACHE", str(tmp_path / "cache"))
    trimesh.creation.icosphere(subdivisions=2).export(tmp_path / "plain.stl")
    database = Database.from_directory(tmp_path, size=(32, 32))
    with pytest.raises(InputError, match="plain.stl: .*needs colours"):
        _ = database["plain"].depth


def test_db_check_lists_meshes_as_a_synthesis_opens_them(tmp_path, monkeypatch, capsys):
    """`imagemap db check` reports the meshes `Database.from_directory` takes as examples,
    a mesh without colours and a name clash as problems (exit code 1)."""
    from imagemap.cli import main
    from imagemap.database import check_database

    monkeypatch.setenv("IMAGEMAP_CACHE", str(tmp_path / "cache"))
    db_dir = tmp_path / "db"
    db_dir.mkdir()
    coloured_sphere(db_dir / "ball.glb", RED)
    rows, problems = check_database(db_dir, size=(40, 30))
    assert problems == []
    assert [(r["name"], r["source"], r["size"]) for r in rows] == [("ball", "ball.glb", "40x30")]
    assert rows[0]["mean_colour"] == pytest.approx(RED, abs=3 / 255)
    assert main(["db", "check", str(db_dir)]) == 0
    assert "mesh ball.glb" in capsys.readouterr().out

    trimesh.creation.icosphere(subdivisions=2).export(db_dir / "plain.stl")
    write_image(db_dir / "ball_depth.png", np.pad(np.ones((10, 10)), 2) * 0.5, bits=16)
    write_image(db_dir / "ball_image.png", np.zeros((14, 14, 3)))
    rows, problems = check_database(db_dir, size=(40, 30))
    assert [r["name"] for r in rows] == ["ball"]  # the pair; the mesh of that name clashes
    assert any("ball.glb: an example named 'ball' exists already" in p for p in problems)
    assert any("plain.stl" in p and "needs colours" in p for p in problems)
    assert main(["db", "check", str(db_dir)]) == 1


def test_a_database_whose_meshes_are_in_its_meshes_folder_gets_a_hint(tmp_path):
    """data_gen's layout: depth examples in OUT/, meshes in OUT/meshes/ (not read by --db OUT)."""
    from imagemap.cli.mesh import mesh_folder_hint

    (tmp_path / "fish_000_depth.png").write_bytes(b"")
    assert mesh_folder_hint(tmp_path) is None  # no meshes/ folder
    (tmp_path / "meshes").mkdir()
    assert mesh_folder_hint(tmp_path) is None  # an empty one
    (tmp_path / "meshes" / "fish_000.glb").write_bytes(b"")
    (tmp_path / "meshes" / "fish_001.glb").write_bytes(b"")
    hint = mesh_folder_hint(tmp_path)
    assert hint is not None and "2 in" in hint and f"--db {tmp_path / 'meshes'}" in hint
    (tmp_path / "other.glb").write_bytes(b"")
    assert mesh_folder_hint(tmp_path) is None  # the folder has mesh examples of its own
