"""PBR material sets (issue #34 item 2): maps beside the colour, through the same source map."""

from __future__ import annotations

import numpy as np
import pytest

from data_gen import CLASSES
from data_gen.core import PART_ROUGHNESS, ROUGHNESS_FROM_PATTERN
from data_gen.dataset import write_class
from imagemap.database import Database
from imagemap.errors import InputError
from imagemap.example import Example
from imagemap.io import read_depth, read_image
from imagemap.materials import (
    NEUTRAL,
    companion_path,
    database_map_kinds,
    decode_normals,
    example_maps,
    transfer_maps,
    with_maps,
)

SIZE = (80, 60)


@pytest.fixture(scope="module")
def fish_db(tmp_path_factory):
    out = tmp_path_factory.mktemp("fish")
    write_class("fish", out, count=4, holdout=1, size=SIZE, quiet=True)
    return out


def test_data_gen_writes_a_material_set_that_follows_the_parts(fish_db):
    database = Database.from_directory(fish_db)
    assert database_map_kinds(database) == ["normal", "roughness", "height", "ao"]
    example = database["fish_000"]
    maps = example_maps(example)
    labels = example.labels
    for part_id, part in enumerate(CLASSES["fish"].parts, start=1):
        here = labels == part_id
        if here.any():
            values = maps["roughness"][here]
            base = PART_ROUGHNESS[part]
            assert values.min() >= base - 1 / 255
            assert values.max() <= base + ROUGHNESS_FROM_PATTERN + 1 / 255
    normals = decode_normals(maps["normal"])
    np.testing.assert_allclose(np.linalg.norm(normals, axis=-1), 1.0, atol=1e-5)
    assert (normals[..., 2] > 0).all()  # tangent space: every normal leaves the surface
    assert normals[example.mask, :2].std() > 0.01  # the relief shows
    assert maps["ao"][~example.mask].min() == 1.0


def test_roughness_follows_the_colours_source_map_pixel_for_pixel(fish_db):
    from imagemap.depth.pipeline import colorize

    database = Database.from_directory(fish_db)
    depth = read_depth(fish_db / "holdout" / "fish_003_depth.png")
    result = colorize(depth, database, preset="fish", seed=0, quiet=True)
    maps = transfer_maps(result, database)
    assert set(maps) == {"normal", "roughness", "height", "ao"}
    rough = maps["roughness"]
    # Independently: each object pixel's source example, row and column.
    ys, xs = np.nonzero(result.mask)
    index, sy, sx = (result.source[ys, xs, k] for k in range(3))
    expected = np.array(
        [
            example_maps(database[result.example_names[i]])["roughness"][y, x]
            for i, y, x in zip(index, sy, sx, strict=True)
        ]
    )
    np.testing.assert_array_equal(rough[ys, xs], expected)
    # The same source map gives the colour's copy: the roughness is not made apart.
    assert len(set(index.tolist())) >= 1
    assert (rough[~result.mask] == NEUTRAL["roughness"][0]).all()
    assert maps["normal"].shape == depth.shape + (3,)


def test_an_example_without_a_map_contributes_its_neutral_value():
    depth = np.pad(np.full((10, 10), 0.5), 1)
    image = np.zeros((12, 12, 3))
    rough = with_maps(Example.from_arrays("a", depth, image), roughness=np.full((12, 12), 0.2))
    plain = Example.from_arrays("b", depth, image)
    source = np.zeros((2, 2, 3), np.int32)
    source[1] = [1, 5, 5]  # second row from "b"
    source[0] = [0, 5, 5]
    from types import SimpleNamespace

    result = SimpleNamespace(source=source, example_names=["a", "b"], mask=np.ones((2, 2), bool))
    maps = transfer_maps(result, [rough, plain])
    np.testing.assert_allclose(maps["roughness"], [[0.2, 0.2], NEUTRAL["roughness"] * 2])
    with pytest.raises(InputError, match="roughness map is 3x3, its example is 12x12"):
        with_maps(plain, roughness=np.zeros((3, 3)))
    with pytest.raises(InputError, match="unknown map 'gloss'"):
        with_maps(plain, gloss=np.zeros((12, 12)))


def test_cli_writes_the_set_beside_the_map_and_checks_it_before_any_work(fish_db, tmp_path, capsys):
    from imagemap.cli import main

    query = fish_db / "holdout" / "fish_003_depth.png"
    out = tmp_path / "out" / "fish.png"
    args = ["synthesize", str(query), "--db", str(fish_db), "--preset", "fish", "-q"]
    # A companion that clashes with another output stops before any synthesis.
    clash = companion_path(out, "roughness")
    assert main([*args, "-o", str(out), "--provenance", str(clash)]) == 2
    assert "roughness map beside -o) and" in capsys.readouterr().err
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())
    assert main([*args, "-o", str(out)]) == 0
    for kind in ("normal", "roughness", "height", "ao"):
        assert companion_path(out, kind).is_file()
    assert read_image(companion_path(out, "normal")).shape == (SIZE[1], SIZE[0], 3)
    again = tmp_path / "plain.png"
    assert main([*args, "-o", str(again), "--no-maps"]) == 0
    assert not companion_path(again, "roughness").exists()


def test_mesh_route_bakes_the_roughness_a_mesh_example_carries(tmp_path, monkeypatch):
    """A mesh example's roughness texture, rendered per view, copied through each view's
    source map and baked like the colour: the example as its own query gets its own
    roughness back where the views see it."""
    import trimesh

    from imagemap.database import database_at_view
    from imagemap.mesh import colorize_mesh
    from imagemap.mesh.maps import with_mesh_maps
    from imagemap.scene import bake_views, load_mesh
    from imagemap.scene.files import export_textured, textured_mesh
    from imagemap.scene.views import parse_views, sample_image

    monkeypatch.setenv("IMAGEMAP_CACHE", str(tmp_path / "cache"))
    ball = trimesh.creation.icosphere(subdivisions=3)
    ball.vertices *= [1.5, 1.0, 0.8]
    uv = (ball.vertices[:, :2] / [3.0, 2.0]) + 0.5
    rows, cols = np.mgrid[0:64, 0:64]
    colour = np.stack([cols / 63, rows / 63, np.full((64, 64), 0.4)], axis=-1)
    rough = np.where(cols < 32, 0.2, 0.8)  # left half glossy, right half rough
    db = tmp_path / "db"
    db.mkdir()
    export_textured(
        textured_mesh(ball.vertices, ball.faces, uv, colour, maps={"roughness": rough}),
        db / "ball.glb",
    )
    mesh = load_mesh(db / "ball.glb")
    views = parse_views("front,back")
    database = Database.from_directory(db, view=views[0], size=(64, 48))
    import inspect

    # The views path (a mesh in its example's own UV layout may go the UV-space way).
    views_path = (
        {"uv_space": False} if "uv_space" in inspect.signature(colorize_mesh).parameters else {}
    )
    from imagemap.depth.units import query_in_database

    with query_in_database():  # the example is its own query, on purpose
        made = colorize_mesh(
            mesh, database, views, size=(64, 48), texture_size=64, preset="busts", **views_path
        )
    databases = [database_at_view(database, v, (64, 48)) for v in views]
    out = with_mesh_maps(
        made.mesh,
        mesh,
        made.renders,
        made.results,
        databases,
        lambda images: bake_views(mesh, made.renders, images, 64),
    )
    packed = np.asarray(out.visual.material.metallicRoughnessTexture.convert("RGB"), np.float32)
    centre = np.full((len(out.faces), 3), 1 / 3)
    face_uv = np.einsum("fk,fkc->fc", centre, out.visual.uv[out.faces])
    baked = sample_image(packed[..., 1:2] / 255.0, face_uv)[:, 0]
    truth_uv = np.einsum("fk,fkc->fc", centre, mesh.visual.uv[mesh.faces])
    truth = np.where(truth_uv[:, 0] < 0.5, 0.2, 0.8)
    away = np.abs(truth_uv[:, 0] - 0.5) > 0.1  # away from the step
    assert np.median(np.abs(baked[away] - truth[away])) < 0.02
    assert np.mean(np.abs(baked[away] - truth[away]) < 0.1) > 0.9
