"""The registered path (#46, item 1): mesh examples in other UV layouts registered to the
query in 3-D and resampled into its atlas, then synthesized there."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from imagemap.database import Database
from imagemap.depth.config import resolve_config
from imagemap.errors import InputError
from imagemap.example import Example
from imagemap.mesh.colorize import (
    colorize_mesh,
    registrable_examples,
    uv_layout_examples,
    with_atlas,
)
from imagemap.mesh.register import (
    Registration,
    deform,
    register_rigid,
    registered_examples,
    resample,
)
from imagemap.mesh.uvspace import same_texel_source
from imagemap.scene import textured_mesh
from imagemap.scene.views import render_mesh, render_textured, texture_image

RED, BLUE = (0.9, 0.1, 0.1), (0.1, 0.2, 0.9)
#: Vertex error of a recovered transform, in RMS radii: ICP on 6000 samples lands within
#: a few thousandths; a wrong start (not mirrored) is off by the body's size (~1).
RECOVERED = 0.02
#: Largest |difference| of a resampled texel from the texture it came from (float32).
SAME_TEXEL = 1e-5
#: Largest move of a mesh deformed onto itself (its size is 2): measured 0.0014.
SELF_DEFORMATION = 0.01
#: Mean |RGB| (0-1) of a side's colour from the truth's: the examples' two tones are
#: 0.8 apart per channel; a side copied from the wrong tone is off by ~1.6 summed.
SIDE_COLOUR = 0.15
#: Half the thickness of the folded sheet below (its layers are 2x this apart).
FOLD = 0.05
#: Vertex error (RMS radii) of a body registered from an example that has a neck more: measured
#: 0.021; with the scale taken from the RMS radii and every pair kept, 0.22.
WITH_A_NECK = 0.08
#: Rows the engine's matches are moved by in the speck test: across the 16^2 working atlas'
#: charts (xatlas packs the lumpy body's in 2-5 texel strips), so most land elsewhere.
SHIFT = 3
#: A texel copied from elsewhere differs from its own by more than this (of 1) on the
#: noise texture (uniform in [0, 1]), as the benchmark counts specks.
ELSEWHERE = 0.1
#: Texels off the example with the moved matches and the copy through them (measured 51
#: of 626; the seams and the blend take some back): well above none.
MOVED_OFF = 20
#: Texels this far (RMS radii) from the example were padding before #46's fix (0.08 then).
FAR = 0.08
#: The example's strip's length as a share of the query's: its far half has no counterpart.
STRIP_SHARE = 0.6
#: A texel resampled from its own surface point, registered onto itself, is at distance 0
#: but for float rounding.
SAME_POINT = 1e-6


def lumpy(radius: float = 1.0, subdivisions: int = 3) -> trimesh.Trimesh:
    """An asymmetric body (an ellipsoid with two bumps off its axes): no rotation or
    reflection maps it onto itself."""
    body = trimesh.creation.icosphere(subdivisions=subdivisions)
    v = body.vertices * [1.6, 1.0, 0.6] * radius
    for centre, height in (((0.8, 0.4, 0.3), 0.35), ((-0.5, -0.5, -0.2), 0.2)):
        v = (
            v
            + height
            * radius
            * body.vertices
            * np.exp(-np.sum((body.vertices - centre) ** 2, axis=1) / 0.08)[:, None]
        )
    return trimesh.Trimesh(v, body.faces, process=False)


def two_tone(mesh: trimesh.Trimesh, flip: bool) -> trimesh.Trimesh:
    """``mesh`` in a layout of its own: two charts, u along x and v along y, the +z side's
    in the atlas' upper half and the -z side's in its lower half (``flip`` turns the atlas
    upside down: another layout), on a texture red above, blue below: the +z side red,
    the -z side blue, whatever the layout."""
    v = mesh.vertices
    u = 0.05 + 0.9 * (v[:, 0] - v[:, 0].min()) / np.ptp(v[:, 0])
    across = 0.2 * (v[:, 1] - v[:, 1].mean()) / np.abs(v[:, 1] - v[:, 1].mean()).max()
    side = np.where(v[:, 2] >= 0, 0.75, 0.25) + across
    texture = np.zeros((8, 8, 3), np.float32)
    texture[:4], texture[4:] = RED, BLUE  # row 0 is the top: v near 1
    if flip:
        side, texture = 1.0 - side, texture[::-1].copy()
    return textured_mesh(v, mesh.faces, np.c_[u, side], texture)


def test_registration_recovers_a_known_turn_and_mirror():
    query = lumpy()
    turn = trimesh.transformations.rotation_matrix(np.radians(35), [0.3, 1.0, 0.2])
    known = turn @ np.diag([1.0, 1.0, -1.0, 1.0])  # turned and mirrored
    known[:3, :3] *= 2.5  # scaled
    known[:3, 3] = (4.0, -1.0, 2.0)  # moved
    example = query.copy()
    example.apply_transform(known)
    fit = register_rigid(example, query, mirror=True)
    radius = np.sqrt(np.mean(np.sum((query.vertices - query.vertices.mean(0)) ** 2, axis=1)))
    error = np.linalg.norm(fit.vertices - query.vertices, axis=1).max() / radius
    assert fit.mirrored and error < RECOVERED, error
    assert fit.matrix[:3, :3] @ known[:3, :3] == pytest.approx(np.eye(3), abs=RECOVERED)
    # Without reflections among the starts the same example cannot be brought back.
    rigid = register_rigid(example, query, mirror=False)
    assert not rigid.mirrored
    assert np.linalg.norm(rigid.vertices - query.vertices, axis=1).max() / radius > 10 * error


def test_a_part_the_query_lacks_does_not_pull_the_fit():
    # The example is the query's body with a neck more (a separate cylinder below it: a
    # fifth more surface), turned, scaled and moved: the body is brought back onto the
    # query's (the neck moves the centroid and the RMS radius; the trimmed similarity
    # leaves its pairs out and fits the scale).
    query = lumpy()
    neck = trimesh.creation.cylinder(radius=0.4, height=0.8, sections=24)
    neck.apply_translation([0.0, -1.4, 0.0])
    known = trimesh.transformations.rotation_matrix(np.radians(10), [0.3, 1.0, 0.2])
    known[:3, :3] *= 2.0
    known[:3, 3] = (1.0, 2.0, 3.0)
    example = trimesh.util.concatenate([lumpy(), neck])
    example.apply_transform(known)
    fit = register_rigid(example, query)
    radius = np.sqrt(np.mean(np.sum((query.vertices - query.vertices.mean(0)) ** 2, axis=1)))
    body = fit.vertices[: len(query.vertices)]
    assert np.linalg.norm(body - query.vertices, axis=1).max() / radius < WITH_A_NECK


def test_an_example_resampled_into_its_own_layout_is_its_texture():
    # A curved sheet, u along x and v along y (one chart covering the whole atlas).
    x, y = np.meshgrid(np.linspace(-1, 1, 17), np.linspace(-0.5, 0.5, 9))
    vertices = np.c_[x.ravel(), y.ravel(), 0.2 * np.sin(2 * x.ravel()) * np.cos(3 * y.ravel())]
    grid = np.arange(17 * 9).reshape(9, 17)
    a, b, c, d = (
        grid[:-1, :-1].ravel(),
        grid[:-1, 1:].ravel(),
        grid[1:, :-1].ravel(),
        grid[1:, 1:].ravel(),
    )
    faces = np.r_[np.c_[a, b, d], np.c_[a, d, c]]
    texture = np.random.default_rng(0).random((32, 32, 3)).astype(np.float32)
    mesh = textured_mesh(vertices, faces, vertices[:, :2] / [2, 1] + 0.5, texture)
    texture = texture_image(mesh)  # as stored (8 bits)
    fit = register_rigid(mesh, mesh)
    assert fit.residual < 1e-9 and np.abs(fit.vertices - mesh.vertices).max() < 1e-9
    # The deformation onto itself barely moves it (its closest points come from sampled
    # candidate faces: a thin side's may be missed).
    assert np.abs(deform(fit, mesh).deformed - mesh.vertices).max() < SELF_DEFORMATION
    out = resample(mesh, fit, mesh, 32)
    assert out.distance.max() < SAME_POINT  # every texel is its own point
    assert np.abs(out.colour - texture).max() < SAME_TEXEL


def _sheet(shape, columns: int, rows: int) -> trimesh.Trimesh:
    """A (columns x rows) grid of ``shape(s, t)`` (s, t in [0, 1]), its first face facing +z."""
    s, t = np.meshgrid(np.linspace(0, 1, columns), np.linspace(0, 1, rows), indexing="ij")
    vertices = shape(s.ravel(), t.ravel())
    grid = np.arange(columns * rows).reshape(columns, rows)
    a, b = grid[:-1, :-1].ravel(), grid[1:, :-1].ravel()
    c, d = grid[1:, 1:].ravel(), grid[:-1, 1:].ravel()
    faces = np.r_[np.c_[a, b, c], np.c_[a, c, d]]
    corners = vertices[faces[0]]
    if np.cross(corners[1] - corners[0], corners[2] - corners[0])[2] < 0:
        faces = faces[:, ::-1]
    return trimesh.Trimesh(vertices, faces, process=False)


def test_the_deformation_does_not_pull_a_back_surface_onto_the_front():
    # A sheet folded in two (a U in x-z, 2 FOLD thick), its upper layer facing +z and its
    # lower one -z (a shell's front and back, or a head's face and mouth bag), onto a flat
    # query facing +z: both layers are FOLD from it, but only the upper one faces alike.
    length, arc = 2.0, np.pi * FOLD

    def fold(s, t):
        along = s * (2 * length + arc)
        turn = (along - length) / FOLD
        x = np.where(along < length, along, length + FOLD * np.sin(np.clip(turn, 0, np.pi)))
        x = np.where(along > length + arc, 2 * length + arc - along, x)
        z = np.where(along < length, FOLD, FOLD * np.cos(np.clip(turn, 0, np.pi)))
        return np.c_[x, t, z]

    example = _sheet(fold, 90, 20)
    query = _sheet(lambda s, t: np.c_[length * s, t, 0 * s], 40, 20)
    v = example.vertices
    fit = Registration(np.eye(4), False, 0.0, v.copy(), v.copy(), example.faces)
    moved = deform(fit, query).deformed
    inner = v[:, 0] < 0.75 * length  # away from the bend
    upper, lower = inner & (v[:, 2] > 0.99 * FOLD), inner & (v[:, 2] < -0.99 * FOLD)
    # The front lands on the query; the back keeps its distance behind it (pulled onto
    # the query too when the normals are not compared: both layers at z = 0).
    assert np.abs(moved[upper, 2]).max() < 0.1 * FOLD
    assert np.median(moved[upper, 2]) - np.median(moved[lower, 2]) > 1.5 * FOLD


def test_an_example_larger_than_the_query_is_not_shrunk_onto_it():
    # The example's sheet is twice the query's length (a head with a longer neck), just
    # above it, rigidly in place: its points over the query stay over the same points.
    # (Moved onto the query's centroid and scaled to its area, as the parts are, a point
    # at x = 1 would go to x = 0.29, and pulls along the normal never bring it back.)
    query = _sheet(lambda s, t: np.c_[2.0 * s, t, 0 * s], 40, 20)
    example = _sheet(lambda s, t: np.c_[4.0 * s, t, 0 * s + FOLD], 80, 20)
    v = example.vertices
    fit = Registration(np.eye(4), False, 0.0, v.copy(), v.copy(), example.faces)
    moved = deform(fit, query).deformed
    over = v[:, 0] < 1.5  # away from the query's end (pulled towards it from beyond)
    assert np.abs(moved[over, :2] - v[over, :2]).max() < 0.1 * FOLD
    assert np.abs(moved[over, 2]).max() < 0.1 * FOLD  # and onto it


def test_the_path_taken(tmp_path):
    """Examples in the query's layout: uv-space; in other layouts: registered; pictures
    only: views."""
    body = lumpy()
    query = two_tone(body, flip=False)
    for name, flip in (("same", False), ("other", True)):
        folder = tmp_path / name
        folder.mkdir()
        two_tone(body, flip).export(folder / f"{name}.glb")
    same, other = (Database.from_directory(tmp_path / n) for n in ("same", "other"))
    assert uv_layout_examples(query, same) is not None
    assert uv_layout_examples(query, other) is None
    assert list(registrable_examples(other)) == ["other"]
    depth = np.full((12, 16), 0.5, np.float32)
    pictures = Database([Example.from_arrays("flat", depth, np.zeros((12, 16, 3), np.float32))])
    assert registrable_examples(pictures) is None
    assert registrable_examples(other, names=["nobody"]) is None


def _side(mesh, view: str) -> np.ndarray:
    image = render_textured(mesh, view, (40, 30))
    return image[render_mesh(mesh, view, (40, 30)).mask].mean(axis=0)


def test_the_far_side_comes_from_the_examples_far_side(tmp_path):
    """One coherent choice for every texel (0.9 s at load 4, 3.4 s at load 9; the file's
    other tests 0.4 s): the query (no UVs: an xatlas atlas is made),
    textured from an example of another layout, is red on its +z side and blue on its -z
    side as the example is. From one view, the views path can only mirror the side it
    sees onto the far side (red on both)."""
    body = lumpy(subdivisions=2)
    folder = tmp_path / "db"
    folder.mkdir()
    two_tone(body, flip=True).export(folder / "tones.glb")
    database = Database.from_directory(folder, size=(40, 30))
    config = resolve_config("humans", m=1)
    made = colorize_mesh(body, database, preset=config, texture_size=32)
    assert made.path == "registered" and made.example_names == ["tones"]
    near, far = _side(made.mesh, "0,0"), _side(made.mesh, "180,0")
    assert np.abs(near - RED).mean() < SIDE_COLOUR and np.abs(far - BLUE).mean() < SIDE_COLOUR
    views = colorize_mesh(body, database, "front", size=(40, 30), preset=config,
                          registered=False)  # fmt: skip
    assert views.path == "views"
    assert np.abs(_side(views.mesh, "180,0") - BLUE).mean() > SIDE_COLOUR


def test_the_engine_runs_coarser_than_the_texture(tmp_path, monkeypatch, caplog):
    """The registered path's engine works at ``REGISTERED_WORKING_SIZE`` (here 16, under
    the 32² texture), and the texture, copied at its own size through the engine's source
    map, still has each side's colour from the example's same side (0.3 s at load 5)."""
    import logging

    import imagemap.mesh.colorize as colorize_module

    monkeypatch.setattr(colorize_module, "REGISTERED_WORKING_SIZE", 16)
    body = lumpy(subdivisions=2)
    folder = tmp_path / "db"
    folder.mkdir()
    two_tone(body, flip=True).export(folder / "tones.glb")
    database = Database.from_directory(folder, size=(40, 30))
    with caplog.at_level(logging.INFO, logger="imagemap"):
        made = colorize_mesh(body, database, preset=resolve_config("humans", m=1), texture_size=32)
    assert made.path == "registered" and made.image.shape[:2] == (32, 32)
    assert "32^2 atlas (engine at 16^2)" in caplog.text
    near, far = _side(made.mesh, "0,0"), _side(made.mesh, "180,0")
    assert np.abs(near - RED).mean() < SIDE_COLOUR and np.abs(far - BLUE).mean() < SIDE_COLOUR


def test_no_texel_takes_its_colour_from_another_texel(monkeypatch):
    """The registered path copies every texel from the same texel of its chosen example
    (#46's specks: an offset into another chart), whatever the engine matched: with the
    engine's matches moved by SHIFT rows, the texture is still the resampled example's,
    texel for texel (0.2 s at load 4). Without ``same_texel`` the moved matches show."""
    import imagemap.mesh.uvspace as uvspace

    real = uvspace.synthesize

    def moved(*args, **kwargs):
        result = real(*args, **kwargs)
        for source in (result.source, result.copy_source):
            if source is not None:
                source[..., 1] = np.clip(source[..., 1] + SHIFT, 0, source.shape[0] - 1)
        return result

    monkeypatch.setattr(uvspace, "synthesize", moved)
    body = lumpy(subdivisions=2)
    example = two_tone(body, flip=True)
    noise = np.random.default_rng(0).random((32, 32, 3)).astype(np.float32)
    example = textured_mesh(example.vertices, example.faces, example.visual.uv, noise)
    query = with_atlas(body)
    examples, _ = registered_examples(query, {"noise": example}, m=1, texture_size=32)
    resampled = examples[0].texture.astype(np.float32) / 255
    config = resolve_config("humans", m=1)
    rows, cols = np.indices((32, 32))
    for same_texel in (True, False):
        made = uvspace.colorize_uv(query, examples, config, size=32, working_size=16,
                                   same_texel=same_texel)  # fmt: skip
        used = made.mask
        own = (made.source[..., 1] == rows) & (made.source[..., 2] == cols)
        off = (np.abs(made.image - resampled).max(axis=2) > ELSEWHERE) & used
        if same_texel:
            assert own[used].all()
            assert np.abs(made.image - resampled)[used].max() < SAME_TEXEL
        else:  # the case can fail: the moved matches copy other texels' colours
            assert off.sum() > MOVED_OFF


def test_same_texel_source_keeps_the_label_and_drops_the_offset():
    """Two charts (columns 0-1, 3); every match at (2, 1), in the left chart."""
    source = np.zeros((3, 4, 3), np.int32)
    source[..., 0] = [[0, 0, 1, 1], [0, 0, 1, 1], [-1, 0, 1, 1]]
    source[..., 1:] = (2, 1)
    mask = np.ones((3, 4), bool)
    mask[:, 2] = False  # padding between the charts
    out = same_texel_source(source, mask, 2)
    assert out[mask, 0].tolist() == [0, 0, 1, 0, 0, 1, 0, 0, 1]  # (2, 0): its neighbours'
    rows, cols = np.indices((3, 4))
    assert (out[..., 1] == rows).all() and (out[..., 2] == cols).all()


def test_a_texel_the_example_passes_far_from_keeps_its_own_closest_point():
    """A query strip longer than the example's (a fin's tip the example's fin lacks): its
    texels beyond the example's end take the colour of the example's strip, not the
    padding's, the nearest texel in the atlas, here another chart's (the body's tan on the
    generated fish's fins, #46). Both meshes: a strip (red in the example's texture) and a
    square 5 apart (blue), the square's chart beside the strip's far end in the atlas."""
    square = _sheet(lambda s, t: np.c_[s, t, np.full_like(s, 5.0)], 3, 3)
    flat = np.zeros((32, 32, 3), np.float32)
    flat[:, :16], flat[:, 16:] = RED, BLUE  # u < 0.5: the strip's chart; above: the square's

    def strip_and_square(length: float, u_end: float) -> trimesh.Trimesh:
        strip = _sheet(lambda s, t: np.c_[length * s, 0.3 * t, 0.0 * s], 9, 3)
        both = trimesh.util.concatenate([strip, square])
        v = both.vertices
        on_strip = v[:, 2] < 2.5
        u = np.where(on_strip, u_end * v[:, 0] / length, 0.5 + 0.45 * v[:, 0])
        w = np.where(on_strip, 0.3 + 0.4 * v[:, 1] / 0.3, 0.3 + 0.4 * v[:, 1])
        return textured_mesh(v, both.faces, np.c_[u, w], flat)

    query = strip_and_square(2.0, 0.47)
    example = strip_and_square(STRIP_SHARE * 2.0, 0.47)
    fit = Registration(np.eye(4), False, 0.0, example.vertices, example.vertices, example.faces)
    out = resample(example, fit, query, 32)
    used = out.maps.mask
    beyond = used & (out.distance > FAR)  # the strip's texels past the example's end
    assert beyond.any() and not beyond[:, 16:].any()  # (all on the strip's chart)
    colour = out.colour[beyond]
    assert np.abs(colour - RED).max() < SIDE_COLOUR  # the strip's red, not the square's blue


def test_a_degenerate_example_is_named_before_any_work():
    query = two_tone(lumpy(subdivisions=1), flip=False)
    flat = trimesh.Trimesh(np.zeros((3, 3)), [[0, 1, 2]], process=False)
    with pytest.raises(InputError, match="mesh example flat: the mesh has no surface"):
        registered_examples(query, {"flat": flat}, m=1, texture_size=16)


def test_the_query_atlas_is_rasterized_once_per_size_for_every_example(monkeypatch):
    """Two examples at the texture's size and the guides' size: the query's atlas
    rasterized twice (once per size; per example and size before, four times), and each
    example's texture, correspondence and guides what its own resampling gives alone."""
    import imagemap.mesh.register as register_module

    calls: list[int] = []
    real = register_module.rasterize_uv

    def counted(uv, faces, size):
        calls.append(size)
        return real(uv, faces, size)

    monkeypatch.setattr(register_module, "rasterize_uv", counted)
    query = two_tone(lumpy(subdivisions=2), flip=False)
    examples = {"a": two_tone(lumpy(1.1, 2), flip=True), "b": two_tone(lumpy(0.9, 2), flip=False)}
    made, _ = registered_examples(query, examples, m=2, texture_size=32, guide_size=16)
    assert sorted(calls) == [16, 32]
    for example in made:
        alone = resample(examples[example.name], example.registration, query, 32)
        assert np.array_equal(example.texture, np.round(alone.colour * 255.0).astype(np.uint8))
        for ours, theirs in zip(example.correspondence, alone.correspondence, strict=True):
            assert np.array_equal(ours, theirs)
        guides = resample(examples[example.name], example.registration, query, 16).maps
        assert np.array_equal(example.maps(16).guides(), guides.guides())
