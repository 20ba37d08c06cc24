"""Issue #46 item 2: the views path copies each view again at the texels' resolution
(:mod:`imagemap.mesh.fineviews`), so a synthesized view coarser than the texels does not
draw its pixels' steps into the texture."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
import trimesh

from imagemap.mesh.fineviews import fine_factor, fine_view
from imagemap.scene.bake import bake_views
from imagemap.scene.views import render_mesh

#: The fine copy's factor in the known answers.
FACTOR = 3
#: The coarse map magnified puts the edge a fine pixel or more off in at least a third of
#: the 90 fine rows (measured: 72 fine pixels on the wrong side); the copy in none.
MAGNIFIED_MIN_WRONG = 30
#: A magnified picture baked at the same points as the coarse one: the textures' mean
#: difference below this and their correlation above the next (random pixels; see the test).
SAME_POINTS_DIFFERENCE = 0.12
SAME_POINTS_CORRELATION = 0.85
#: The known normal pattern's test: the fine copy's factor and the atlas' side (3.2
#: texels a view pixel, 0.8 a fine pixel).
FACTOR_MAPS = 4
TEXELS = 64
#: Texels (of 2704 inner ones) on the wrong side of the pattern's edge: the fine copy's
#: bake at most this many (texels whose centre lies within a fine pixel of the edge,
#: where the bilinear reads mix both sides: measured 8 of the edge's ~52 rows), the
#: coarse bake at least the next (the view's pixels' steps, 3.2 texels: measured 34).
FINE_MAX_WRONG = 12
COARSE_MIN_WRONG = 24


def _edge(size: int, slope: float) -> np.ndarray:
    """A picture (size x size, RGB) dark below the line y = slope x + size / 4, light above."""
    yy, xx = np.mgrid[:size, :size] + 0.5
    light = (yy < slope * xx + size / 4).astype(np.float32)
    return np.repeat(light[..., None], 3, axis=2)


def test_a_mirrored_patch_is_copied_at_the_examples_fine_edge():
    """The synthesized map (30 x 30) copies a mirrored example (its columns backwards):
    copied again at 3x from the example rendered at 3x, the edge is the fine example's
    own (mirrored) edge; the coarse map magnified has its pixels' steps."""
    fine_example = _edge(90, 0.45)
    coarse_example = fine_example[1::FACTOR, 1::FACTOR]
    source = np.zeros((30, 30, 3), np.int32)
    source[..., 1] = np.arange(30)[:, None]
    source[..., 2] = 29 - np.arange(30)[None, :]
    image = coarse_example[:, ::-1]
    result = SimpleNamespace(image=image, mask=np.ones((30, 30), bool), source=source)
    out = fine_view(result, [coarse_example], [fine_example], FACTOR)
    truth = fine_example[:, ::-1, 0] > 0.5
    magnified = np.repeat(np.repeat(image[..., 0], FACTOR, 0), FACTOR, 1) > 0.5
    assert np.count_nonzero((out[..., 0] > 0.5) != truth) == 0
    assert np.count_nonzero(magnified != truth) >= MAGNIFIED_MIN_WRONG


def test_a_turned_patch_is_copied_at_its_turn_and_a_lone_pixel_as_itself():
    """A patch turned by 90 degrees (rows run along the example's columns) is read at the
    turned fine positions between its pixels' centres; a lone pixel of another example
    in it reads its own source moved by the fine pixel's offset (a translated copy)."""
    from imagemap.mesh.fineviews import fine_source

    source = np.zeros((4, 5, 3), np.int32)
    source[..., 1] = 20 - np.arange(5)[None, :]  # example row falls as the column grows
    source[..., 2] = np.arange(4)[:, None] + 3  # example column grows with the row
    source[2, 2] = (1, 7, 9)  # a lone pixel of example 1
    fine = fine_source(SimpleNamespace(source=source, mask=np.ones((4, 5), bool)), FACTOR)
    offset = (np.arange(FACTOR) + 0.5) / FACTOR - 0.5
    # Fine rows and columns between the centres of coarse pixels (0, 0) and (1, 1): no
    # neighbour of example 1 among their four.
    at = np.arange(FACTOR // 2, FACTOR + FACTOR // 2)
    u = (at + 0.5) / FACTOR - 0.5
    assert np.allclose(fine.y[np.ix_(at, at)], 20 - u[None, :])
    assert np.allclose(fine.x[np.ix_(at, at)], 3 + u[:, None])
    lone = (slice(2 * FACTOR, 3 * FACTOR), slice(2 * FACTOR, 3 * FACTOR))
    assert (fine.index[lone] == 1).all()
    assert np.allclose(fine.y[lone], 7 + offset[:, None])
    assert np.allclose(fine.x[lone], 9 + offset[None, :])


def test_the_factor_reaches_one_texel_per_pixel():
    """A 2 x 2 sheet at 512 texels seen at 200x150 (1.68 cm pixels, 0.39 cm texels)
    needs 4.3x: capped at 4; at 64 texels 200x150 is fine enough already."""
    sheet = trimesh.creation.box(extents=(2.0, 2.0, 0.01))
    sheet.visual = trimesh.visual.TextureVisuals(uv=sheet.vertices[:, :2] / 2 + 0.5)
    assert fine_factor(sheet, ["front"], (200, 150), 512) == 4
    assert fine_factor(sheet, ["front"], (200, 150), 128) == 2
    assert fine_factor(sheet, ["front"], (200, 150), 64) == 1


def test_the_bake_samples_a_finer_image_at_the_same_points():
    """A view's map at 3x its render's size is baked from the same surface points: a
    picture that is the coarse one magnified (each pixel 3 x 3) bakes to the coarse
    one's texture where a texel's point falls in a pixel's middle third, and close to it
    elsewhere."""
    box = trimesh.creation.box(extents=(2.0, 1.0, 1.0)).subdivide().subdivide()
    box.visual = trimesh.visual.TextureVisuals(uv=np.c_[box.vertices[:, 0] / 2 + 0.5,
                                                        box.vertices[:, 1] + 0.5])  # fmt: skip
    renders = [render_mesh(box, v, (24, 18)) for v in ("front", "back")]
    rng = np.random.default_rng(0)
    coarse = [rng.random((18, 24, 3)).astype(np.float32) for _ in renders]
    fine = [np.repeat(np.repeat(c, FACTOR, 0), FACTOR, 1) for c in coarse]
    a = bake_views(box, renders, coarse, 32, texture_only=True)
    b = bake_views(box, renders, fine, 32, texture_only=True)
    assert a.shape == b.shape
    # Bilinear between other neighbours: equal only in a pixel's middle, close on the
    # whole (measured 0.077 mean difference, correlation 0.93; read at the coarse
    # points without the factor, the fine picture's corner would give 0.28 and -0.05).
    assert np.mean(np.abs(a - b)) < SAME_POINTS_DIFFERENCE
    assert np.corrcoef(a.ravel(), b.ravel())[0, 1] > SAME_POINTS_CORRELATION


def test_a_prepared_set_renders_the_pictures_the_database_caches(
    shared_heads, tmp_path, monkeypatch
):
    """A batch's prepared set has no file: a mesh example at a size it was not prepared
    for is rendered from the mesh it ships, the same array as the single command's
    cached render (so the batch writes the same bytes), and kept for the next object."""
    from imagemap.database import Database
    from imagemap.mesh.library import ExampleSet
    from imagemap.scene.views import FRONT

    monkeypatch.setenv("IMAGEMAP_CACHE", str(tmp_path / "cache"))
    database = ExampleSet.of(Database.from_directory(shared_heads))
    prepared = database.prepared([FRONT], (32, 24), pictures=False)
    assert prepared.source is None
    fine = (96, 72)
    made = prepared.picture("head_00", FRONT, fine)
    assert made.shape == (72, 96, 3)
    assert np.array_equal(made, database.picture("head_00", FRONT, fine))
    assert prepared.picture("head_00", FRONT, fine) is made
    # (Its PBR maps: these heads carry none; the slow batch-equals-single test's
    # normal- and roughness-mapped example compares them byte for byte.)


def _tilted(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The known normal pattern on the sheet: tilted towards +x (0.6, 0, 0.8) right of
    the slanted line x = 0.3 y + 0.1, flat left of it; encoded (H, W, 3)."""
    tilted = (x > 0.3 * y + 0.1)[..., None]
    return np.where(tilted, [0.8, 0.5, 0.9], [0.5, 0.5, 1.0]).astype(np.float32)


def _pixel_centres(render, factor: int) -> tuple[np.ndarray, np.ndarray]:
    """World x, y of a front view's pixel centres at ``factor`` times its size."""
    width, height = render.size
    step = render.pixel_size / factor
    cols = (np.arange(width * factor) + 0.5) * step - width * render.pixel_size / 2
    rows = (np.arange(height * factor) + 0.5) * step - height * render.pixel_size / 2
    return np.meshgrid(render.center[0] + cols, render.center[1] - rows)


def test_the_fine_copy_bakes_an_examples_normal_pattern_at_the_texels_resolution():
    """A flat sheet seen from the front at 32x24 (3.2 texels of its 64^2 atlas a pixel)
    copies an example whose normal map (and roughness, the same pattern) has a slanted
    edge. Copied through the colour's fine copy at 4x and baked, every map is the pattern
    at the texels' resolution: the edge within a texel of the truth; baked from the
    view's own maps (the coarse bake), the edge is stepped by the view's pixels."""
    from imagemap.mesh.fineviews import fine_maps, fine_source
    from imagemap.mesh.maps import bake_maps

    sheet = trimesh.Trimesh([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0.0]],
                            [[0, 1, 2], [0, 2, 3]], process=False)  # fmt: skip
    sheet.visual = trimesh.visual.TextureVisuals(uv=sheet.vertices[:, :2] / 2 + 0.5)
    render = render_mesh(sheet, "front", (32, 24))
    source = np.zeros((24, 32, 3), np.int32)
    source[..., 1], source[..., 2] = np.mgrid[:24, :32]
    result = SimpleNamespace(mask=render.mask, source=source, example_names=["a"])
    coarse = _tilted(*_pixel_centres(render, 1))
    fine = _tilted(*_pixel_centres(render, FACTOR_MAPS))
    maps = {"normal": fine, "roughness": fine[..., 0]}
    copied = fine_maps(fine_source(result, FACTOR_MAPS), [coarse.shape], [maps])
    assert copied["normal"].shape == (24 * FACTOR_MAPS, 32 * FACTOR_MAPS, 3)

    def bake(images, picture_normals=False):
        return bake_views(sheet, [render], images, TEXELS, texture_only=True,
                          picture_normals=picture_normals)  # fmt: skip

    baked_fine = bake_maps(sheet, [render], [copied], bake, sheet,
                           bake_normals=lambda images: bake(images, True))  # fmt: skip
    baked_coarse = bake_maps(sheet, [render], [{"normal": coarse, "roughness": coarse[..., 0]}],
                             bake, sheet)  # fmt: skip
    centre = (np.arange(TEXELS) + 0.5) / TEXELS * 2 - 1
    u, v = np.meshgrid(centre, -centre)  # row 0 is v = 1
    truth = _tilted(u, v)[..., 0] > 0.65
    # Away from the sheet's border (the views' silhouette margin).
    inner = (np.abs(u) < 0.8) & (np.abs(v) < 0.8)
    for name, baked in (("fine", baked_fine), ("coarse", baked_coarse)):
        for kind in ("normal", "roughness"):
            values = baked[kind][..., 0] if kind == "normal" else baked[kind]
            wrong = np.count_nonzero(((values > 0.65) != truth) & inner)
            if name == "fine":
                assert wrong <= FINE_MAX_WRONG, (kind, wrong)
            else:
                assert wrong >= COARSE_MIN_WRONG, (kind, wrong)
    # The tilt is the example's, in the frames of the sheet's tangents (u along x).
    tilted = truth & inner & (np.abs(u - (0.3 * v + 0.1)) > 0.1)
    decoded = baked_fine["normal"][tilted] * 2 - 1
    assert np.allclose(decoded, [0.6, 0.0, 0.8], atol=0.02)


def test_one_view_projects_a_picture_copied_finer_over_the_same_picture():
    """One view (projection UVs): a map a whole factor finer than its render is the
    texture itself, over the same picture (the UVs equal the coarse projection's), so a
    face samples the fine map where it sampled the coarse one; a map of another size is
    refused."""
    from imagemap.io import InputError
    from imagemap.scene.bake import project_texture

    box = trimesh.creation.box(extents=(2.0, 1.0, 1.0))
    render = render_mesh(box, "front", (24, 18))
    rng = np.random.default_rng(1)
    coarse = rng.random((18, 24, 3)).astype(np.float32)
    fine = np.repeat(np.repeat(coarse, FACTOR, 0), FACTOR, 1)
    a = project_texture(box, render, coarse)
    b = project_texture(box, render, fine)
    assert np.array_equal(a.visual.uv, b.visual.uv)
    texture = project_texture(box, render, fine, texture_only=True)
    assert texture.shape == (18 * FACTOR, 24 * FACTOR, 3)
    # Inside the object the texture is the fine map itself.
    inside = np.repeat(np.repeat(render.mask, FACTOR, 0), FACTOR, 1)
    assert np.array_equal(texture[inside], fine[inside])
    with pytest.raises(InputError, match="does not match the render"):
        project_texture(box, render, fine[:-1])
