"""Meshes whose views agree (#32, item 3): one choice of examples per object, a bake that
takes each texel from one view, the texture at the atlas' resolution, and the synthesis in
a shared UV layout."""

from __future__ import annotations

import json
import logging
from pathlib import Path

import numpy as np
import pytest
import trimesh
from scipy import ndimage

from imagemap.database import Database, database_at_view
from imagemap.depth.selection import select_examples
from imagemap.io import InputError
from imagemap.mesh.colorize import colorize_mesh, selection_distances, shared_examples
from imagemap.mesh.uvspace import (
    LAYOUT_TEST_SIZE,
    layout_agreement,
    mesh_uv_arrays,
    same_uv_layout,
    shares_layout,
    surface_maps,
)
from imagemap.scene import bake_views, load_mesh, render_mesh, textured_mesh
from imagemap.scene.bake import SEAM_BAND_PIXELS, texture_size_for, view_shares, world_per_uv
from imagemap.scene.views import texture_image

RED, GREEN, BLUE = (0.9, 0.1, 0.1), (0.1, 0.8, 0.2), (0.1, 0.2, 0.9)


def bumped_body(front: float, back: float) -> trimesh.Trimesh:
    """An ellipsoid with a bump of height ``front`` on its +z side and ``back`` on -z."""
    body = trimesh.creation.icosphere(subdivisions=3)
    v = body.vertices * [1.5, 1.0, 0.6]
    for height, sign in ((front, 1.0), (back, -1.0)):
        spot = np.exp(-((v[:, 0] - 0.3 * sign) ** 2 + v[:, 1] ** 2) / 0.1)
        v[:, 2] += sign * height * spot * (np.sign(v[:, 2]) == sign)
    return trimesh.Trimesh(v, body.faces, process=False)


def write_coloured(path: Path, mesh: trimesh.Trimesh, colour) -> None:
    uv = np.zeros((len(mesh.vertices), 2)) + 0.5
    texture = np.ones((4, 4, 3), np.float32) * np.asarray(colour, np.float32)
    textured_mesh(mesh.vertices, mesh.faces, uv, texture).export(path)


@pytest.fixture
def bump_database(tmp_path, monkeypatch):
    """Examples that the front and the back view would each choose differently."""
    monkeypatch.setenv("IMAGEMAP_CACHE", str(tmp_path / "cache"))
    root = tmp_path / "db"
    root.mkdir()
    write_coloured(root / "front_bump.glb", bumped_body(0.5, 0.0), RED)
    write_coloured(root / "back_bump.glb", bumped_body(0.0, 0.3), BLUE)
    write_coloured(root / "plain.glb", bumped_body(0.0, 0.0), GREEN)
    return root


def test_views_of_one_object_use_the_same_examples(bump_database):
    query = bumped_body(0.5, 0.3)
    size = (48, 36)
    database = Database.from_directory(bump_database, size=size)
    renders = [render_mesh(query, view, size) for view in ("front", "back")]
    at_view = [database_at_view(database, r.view, size) for r in renders]
    # Chosen view by view, the front and the back want other examples...
    alone = [at_view[k].names[select_examples(r.depth, at_view[k], m=1)[0]]
             for k, r in enumerate(renders)]  # fmt: skip
    assert alone[0] != alone[1]
    # ... chosen once for the object, every view takes the one nearest over both, each
    # view's distances per object pixel weighted by the share of the surface it sees best.
    shares = view_shares(query, renders)
    assert shares.sum() == pytest.approx(1.0) and (shares > 0.3).all()
    total = sum(w * selection_distances(r.depth, db) / r.mask.sum()
                for w, r, db in zip(shares, renders, at_view, strict=True))  # fmt: skip
    nearest = database.names[int(np.argmin(total))]
    made = colorize_mesh(query, database, "front,back", size=size, preset="humans",
                         texture_size=32, registered=False)  # fmt: skip
    assert [r.example_names for r in made.results] == [[nearest], [nearest]]
    assert made.path == "views"
    two = colorize_mesh(query, database, "front,back", size=size, preset="humans", m=2,
                        texture_size=32, registered=False)  # fmt: skip
    assert sorted(two.results[0].example_names) == sorted(two.results[1].example_names)
    assert shared_examples(renders, at_view, 2, shares) == two.results[0].example_names
    # A view that gives the texture nothing does not choose: the front's own choice.
    assert shared_examples(renders, at_view, 1, np.array([1.0, 0.0])) == [alone[0]]


def test_selection_distances_rank_as_select_examples(bump_database):
    size = (48, 36)
    database = database_at_view(Database.from_directory(bump_database, size=size), "front", size)
    depth = render_mesh(bumped_body(0.2, 0.1), "front", size).depth
    order = np.argsort(selection_distances(depth, database), kind="stable")
    assert order.tolist() == select_examples(depth, database, m=3)


def test_bake_of_two_views_that_disagree_shows_no_average():
    sphere = trimesh.creation.icosphere(subdivisions=3)
    renders = [render_mesh(sphere, view, size=(48, 48)) for view in ("front", "right")]
    images = [np.broadcast_to(np.float32(c), (48, 48, 3)) for c in (RED, BLUE)]
    baked, views = bake_views(sphere, renders, images, texture_size=128, return_views=True)
    texture = texture_image(baked)
    vertices, faces, uv = baked.vertices, baked.faces, baked.visual.uv
    seen = views >= 0  # texels of the charts that a view sees
    assert (views[seen] == 0).any() and (views[seen] == 1).any()
    # The band: SEAM_BAND_PIXELS view pixels in texels, each way from a boundary.
    texel_world = np.sqrt(world_per_uv(vertices, faces, uv)) / 128
    band = SEAM_BAND_PIXELS * renders[0].pixel_size / texel_world
    far = {}
    for view in (0, 1):
        other = seen & (views != view)
        distance = ndimage.distance_transform_cdt(~other, metric="chessboard")
        far[view] = seen & (views == view) & (distance > 2 * np.ceil(band / 2))
    red, blue = (np.round(np.array(c) * 255) / 255 for c in (RED, BLUE))
    np.testing.assert_allclose(texture[far[0]], np.broadcast_to(red, (far[0].sum(), 3)), atol=1e-6)
    np.testing.assert_allclose(texture[far[1]], np.broadcast_to(blue, (far[1].sum(), 3)), atol=1e-6)
    # Away from the seams no texel is a mix (the cos^2 average of the old bake made the
    # whole overlap of the two views purple).
    pure = np.isclose(texture[seen], red, atol=2 / 255).all(axis=1) | np.isclose(
        texture[seen], blue, atol=2 / 255
    ).all(axis=1)
    assert pure.mean() > 0.85
    assert (far[0] | far[1]).sum() > 0.8 * seen.sum()


def test_texture_size_follows_the_mesh(shared_heads):
    head = load_mesh(shared_heads / "head_00.glb")
    # Its own texture's; the texel density alone would ask for 1024 (814 texels across).
    assert texture_size_for(head, pixel_size=0.01) == 128
    plane = trimesh.creation.box(extents=(2.0, 2.0, 0.01))
    uv = plane.vertices[:, :2] / 2 + 0.5
    plane.visual = trimesh.visual.TextureVisuals(uv=uv)
    # 2 world units over the UV square: 2 texels per view pixel of 0.01 -> 400 -> 512.
    assert texture_size_for(plane, pixel_size=0.01) == 512
    assert texture_size_for(plane, pixel_size=0.1) == 64


def test_shared_layout_is_detected_and_a_mirrored_one_is_not(shared_heads):
    first = load_mesh(shared_heads / "head_00.glb")
    second = load_mesh(shared_heads / "head_01.glb")
    assert same_uv_layout(first, second)
    mirrored = second.copy()
    uv = mirrored.visual.uv.copy()
    uv[:, 0] = 1.0 - uv[:, 0]
    mirrored.visual = trimesh.visual.TextureVisuals(uv=uv)
    assert not same_uv_layout(first, mirrored)
    maps = [surface_maps(*mesh_uv_arrays(m), LAYOUT_TEST_SIZE) for m in (first, second, mirrored)]
    iou, distance = layout_agreement(maps[0], maps[1])
    assert iou > 0.99 and distance < 0.05  # measured 1.0 and 0.019: two people, one layout
    # The mirrored layout covers the same texels, but with the other side of the head.
    iou, distance = layout_agreement(maps[0], maps[2])
    assert iou > 0.9 and distance > 0.5  # measured 1.0 and 0.61
    assert shares_layout(first, second) and not shares_layout(first, mirrored)
    # Another topology in the same layout: the same surface with its vertices and faces
    # numbered backwards is not the same mesh, but the same layout.
    remeshed = trimesh.Trimesh(second.vertices[::-1], (len(second.vertices) - 1 - second.faces),
                               process=False)  # fmt: skip
    remeshed.visual = trimesh.visual.TextureVisuals(uv=second.visual.uv[::-1])
    assert not same_uv_layout(first, remeshed) and shares_layout(first, remeshed)


def test_uv_space_synthesis_of_an_examples_own_mesh_copies_its_texels(shared_heads, caplog):
    database = Database.from_directory(shared_heads)
    mesh = load_mesh(shared_heads / "head_00.glb")
    truth = texture_image(mesh)
    with caplog.at_level(logging.INFO, logger="imagemap"):
        made = colorize_mesh(mesh, database, preset="busts", seed=0)
    assert made.path == "uv-space"
    assert "uv-space path" in caplog.text
    result = made.results[0]
    assert result.example_names[0] == "head_00"  # its own surface is the nearest
    used = result.mask
    source = result.source[used]
    rows, cols = np.nonzero(used)
    own = (source[:, 0] == 0) & (source[:, 1] == rows) & (source[:, 2] == cols)
    assert own.mean() > 0.95  # the source map points at the same texels
    error = np.abs(texture_image(made.mesh)[used] - truth[used]).mean() * 255
    assert error < 2.0  # measured 0.0 (the other head's texture differs by 42 on average)
    other = texture_image(load_mesh(shared_heads / "head_01.glb"))
    assert np.abs(other[used] - truth[used]).mean() * 255 > 10


def test_uv_space_refuses_what_it_cannot_do(shared_heads, tmp_path, monkeypatch):
    monkeypatch.setenv("IMAGEMAP_CACHE", str(tmp_path / "cache"))
    database = Database.from_directory(shared_heads)
    plain = trimesh.creation.icosphere(subdivisions=2)  # no UVs
    with pytest.raises(InputError, match="uv-space: the query mesh has no UV"):
        colorize_mesh(plain, database, uv_space=True)
    head = load_mesh(shared_heads / "head_00.glb")
    with pytest.raises(InputError, match="no example named"):
        colorize_mesh(head, database, uv_space=True, examples=["nobody"])


def test_cli_says_which_path_ran_and_refuses_uv_space_without_uvs(shared_heads, tmp_path, capsys):
    from imagemap.cli import main

    out, report = tmp_path / "head.glb", tmp_path / "report.json"
    args = ["synthesize", str(shared_heads / "head_00.glb"), "--db", str(shared_heads)]
    assert main([*args, "--exclude", "head_00", "-o", str(out), "--report", str(report)]) == 0
    assert json.loads(report.read_text())["path"] == "uv-space"
    err = capsys.readouterr().err
    assert "uv-space path" in err and "its UV atlas" in err
    made = load_mesh(out)
    assert texture_image(made).shape == (128, 128, 3)  # the query's own texture's size
    plain = tmp_path / "plain.ply"
    trimesh.creation.icosphere(subdivisions=2).export(plain)
    code = main(["synthesize", str(plain), "--db", str(shared_heads), "--uv-space", "-o",
                 str(tmp_path / "plain.glb")])  # fmt: skip
    assert code == 2
    assert "--uv-space: the query mesh has no UV coordinates" in capsys.readouterr().err
    assert not (tmp_path / "plain.glb").exists()


def test_a_placeholder_texture_does_not_size_the_uv_paths_output(shared_heads):
    from imagemap.mesh.colorize import _atlas_size

    head = load_mesh(shared_heads / "head_00.glb")
    examples = [texture_image(load_mesh(shared_heads / "head_01.glb"))]  # 128^2
    vertices, faces, uv = mesh_uv_arrays(head)
    grey = textured_mesh(vertices, faces, uv, np.full((2, 2, 3), 0.5, np.float32))
    assert _atlas_size(grey, examples) == 128  # not 2: the examples' size
    own = textured_mesh(vertices, faces, uv, np.full((256, 256, 3), 0.5, np.float32))
    assert _atlas_size(own, examples) == 256  # a real texture of its own keeps its size
