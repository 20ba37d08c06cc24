"""The last defects of the 432-case hostile pass (issue #45), each a case here.

The house style of tests/test_hostile.py: every refused case asserts the exit code, a
message naming the file or option, and the SHA-256 of every file under the test folder
before and after (no input or earlier output changed, nothing new written); no synthesis
may start before a refusal. Then the silent cases made loud: data_gen onto a database of
other settings, photometric stereo on lights that cannot decide a normal, meshes with
non-finite vertices or UVs, and the API arguments and files that were taken as they came.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import trimesh
from test_hostile import assert_unchanged, cli, depth16, run_refused, snapshot, write_database

import imagemap.batch.work
import imagemap.depth.pipeline
import imagemap.mesh
import imagemap.mesh.colorize
from imagemap.io import InputError, write_image
from imagemap.scene import export_textured, textured_mesh

#: The PBR maps data_gen writes beside every instance (held-out truths too).
TRUTH_MAPS = ("normal", "roughness", "height", "ao")


def ball(stretch=(1.5, 1.0, 0.8)):
    """A small textured ellipsoid (UVs from x, y)."""
    mesh = trimesh.creation.icosphere(subdivisions=2)
    mesh.vertices *= stretch
    uv = mesh.vertices[:, :2] / (2 * np.asarray(stretch[:2])) + 0.5
    texture = np.full((16, 16, 3), 0.5)
    texture[:8] = (0.8, 0.3, 0.2)
    return textured_mesh(mesh.vertices, mesh.faces, uv, texture)


def _truth(folder: Path, name: str, example) -> None:
    """``name``'s depth and its truth as data_gen --holdout writes them: image, labels,
    JSON and the PBR maps."""
    write_image(folder / f"{name}_depth.png", depth16(example.depth))
    write_image(folder / f"{name}_image.png", example.image)
    write_image(folder / f"{name}_labels.png", (example.depth > 0.5).astype(np.uint8))
    (folder / f"{name}.json").write_text(json.dumps({"name": name}))
    for kind in TRUTH_MAPS:
        shape = example.depth.shape + ((3,) if kind == "normal" else ())
        write_image(folder / f"{name}_{kind}.png", np.full(shape, 0.25))


@pytest.fixture
def fish(tmp_path, tmp_path_factory, blob_database, monkeypatch):
    """fish/ as data_gen --holdout --meshes lays it out: pictures with roughness maps,
    meshes/ (the mesh database), holdout/ (two queries q, r with their whole truths) and
    holdout/meshes/q.glb (the mesh of q, whose truth is one folder up)."""
    monkeypatch.setenv("IMAGEMAP_CACHE", str(tmp_path_factory.mktemp("cache")))
    root = tmp_path / "fish"
    root.mkdir()
    write_database(root, blob_database)
    for example in blob_database:
        write_image(root / f"{example.name}_roughness.png", np.full(example.depth.shape, 0.7))
    export_textured(ball((1.4, 1.0, 0.7)), root / "meshes" / "blob_0.glb")
    holdout = root / "holdout"
    holdout.mkdir()
    _truth(holdout, "q", blob_database[1])
    _truth(holdout, "r", blob_database[3])
    export_textured(ball((1.3, 1.0, 0.9)), holdout / "meshes" / "q.glb")
    return {"root": tmp_path, "db": root, "holdout": holdout, "mesh": holdout / "meshes" / "q.glb"}


def _depths(w, *names, db=None, extra=()):
    queries = [str(w["holdout"] / f"{n}_depth.png") for n in names]
    return ["synthesize", *queries, "--db", str(db or w["db"]), "-q", *extra]


def _mesh(w, *extra):
    return ["synthesize", str(w["mesh"]), "--db", str(w["db"] / "meshes"), "-q", "--view=front",
            "--size", "32x24", "--texture-size", "16", *extra]  # fmt: skip


# -- Lost (5): no example or truth is an output without --overwrite ---------------------------

LOST_CASES = {
    # 1. several depths into the query folder with --overwrite: the PBR truths stay.
    "lost 1: several depths into their folder with --overwrite (PBR truths)": (
        lambda w: _depths(w, "q", "r", extra=["-o", str(w["holdout"]), "--overwrite"]),
        ["q_roughness.png", "--overwrite replaces", "never a roughness map", "--no-maps"],
    ),
    "lost 1: -o onto a PBR truth with --overwrite": (
        lambda w: _depths(w, "q", extra=["-o", str(w["holdout"] / "r_height.png"), "--overwrite"]),
        ["r_height.png", "never a height map"],
    ),
    # 3. a mesh's output onto its object's truth (one folder above the mesh).
    "lost 3: a mesh's map onto its truth": (
        lambda w: _mesh(w, "-o", str(w["holdout"] / "q_image.png")),
        ["q_image.png", "held-out truth", "q_depth.png", "--overwrite"],
    ),
    "lost 3: a mesh's report onto its truth's sidecar": (
        lambda w: _mesh(
            w, "-o", str(w["root"] / "m.glb"), "--report", str(w["holdout"] / "q.json")
        ),
        ["q.json", "--report", "held-out truth"],
    ),
    # 4. a mesh's output into the picture database one folder above --db.
    "lost 4: a mesh's map onto an example of the database above --db": (
        lambda w: _mesh(w, "-o", str(w["db"] / "blob_0_image.png")),
        ["blob_0_image.png", "example", "blob_0_depth.png"],
    ),
    "lost 4: a mesh's provenance onto an example's labels": (
        lambda w: _mesh(
            w, "-o", str(w["root"] / "m.glb"), "--provenance", str(w["db"] / "blob_2_labels.png")
        ),
        ["blob_2_labels.png", "--provenance"],
    ),
    # 5. a depth query's output onto another query's truth.
    "lost 5: -o onto another query's truth": (
        lambda w: _depths(w, "q", extra=["-o", str(w["holdout"] / "r_image.png")]),
        ["r_image.png", "held-out truth", "r_depth.png", "--overwrite"],
    ),
    "lost 5: --preview onto another query's labels": (
        lambda w: _depths(
            w,
            "q",
            extra=["-o", str(w["root"] / "m.png"), "--preview", str(w["holdout"] / "r_labels.png")],
        ),
        ["r_labels.png", "--preview"],
    ),
    "an output onto another query's depth map (even with --overwrite)": (
        lambda w: _depths(w, "q", extra=["-o", str(w["holdout"] / "r_depth.png"), "--overwrite"]),
        ["r_depth.png", "depth map"],
    ),
}


@pytest.mark.parametrize("case", sorted(LOST_CASES))
def test_no_example_or_truth_is_an_output(fish, capsys, no_work, case):
    build, words = LOST_CASES[case]
    run_refused(fish, capsys, build(fish), words)


def test_batch_replaces_no_example_even_one_it_claims(fish, capsys, no_work):
    """A batch has no --overwrite: an example's file in -o is refused even when an earlier
    batch's manifest names it."""
    inputs = fish["root"] / "in"
    inputs.mkdir()
    write_image(inputs / "blob_3_depth.png", np.zeros((8, 8)) + 0.5)
    done = fish["root"] / "out" / ".imagemap-done"
    done.mkdir(parents=True)
    out = fish["root"] / "out"
    (out / "blob_3_depth.png").write_bytes((fish["db"] / "blob_3_depth.png").read_bytes())
    (out / "blob_3_image.png").write_bytes((fish["db"] / "blob_3_image.png").read_bytes())
    (done / "blob_3_depth.png.json").write_text(json.dumps({"outputs": {"blob_3_image.png": "x"}}))
    argv = ["batch", str(inputs), "--db", str(fish["db"] / "meshes"), "-o", str(out), "-q"]
    run_refused(fish, capsys, argv, ["blob_3_image.png", "example or held-out truth"])


def test_overwrite_replaces_the_truths_it_names_and_nothing_else(fish, capsys):
    """Lost 1 as the user met it: several depths into their folder with --overwrite is
    refused (the maps would replace the PBR truths); with --no-maps it replaces
    NAME_image.png of each query and leaves every other file byte for byte."""
    before = snapshot(fish["root"])
    argv = _depths(fish, "q", "r", extra=["-o", str(fish["holdout"]), "--overwrite"])
    code, message = cli(argv, capsys)
    assert code == 2 and "q_roughness.png" in message, message
    assert_unchanged(fish, before)
    code, message = cli([*argv, "--no-maps"], capsys)
    assert code == 0, message
    after = snapshot(fish["root"])
    changed = sorted(name for name in before if after[name] != before[name])
    assert changed == ["fish/holdout/q_image.png", "fish/holdout/r_image.png"]
    assert set(after) == set(before)


def test_the_rule_knows_a_set_of_its_own_from_an_example(tmp_path):
    """``x.json`` beside a mesh ``x.glb`` is an example's sidecar, unless this command
    writes ``x.glb`` too (``-o x.glb --report x.json`` run again)."""
    from imagemap.outputs import OutputPlan

    for name in ("x.glb", "x.json"):
        (tmp_path / name).write_text("earlier")
    again = OutputPlan()
    again.add_output(tmp_path / "x.glb", "-o")
    again.add_output(tmp_path / "x.json", "--report")
    again.check()
    alone = OutputPlan(overwrite=False)
    alone.add_output(tmp_path / "x.json", "--report")
    with pytest.raises(InputError, match=r"x\.json.*sidecar.*x\.glb.*--overwrite"):
        alone.check()


# -- data_gen onto an existing database (lost 2) -----------------------------------------------


@pytest.fixture(scope="module")
def earlier_run(tmp_path_factory):
    """An earlier data_gen run: fish, 3 instances at 40x30, one held out."""
    from data_gen.__main__ import main as data_gen_main

    out = tmp_path_factory.mktemp("earlier") / "fish"
    args = ["fish", "--count", "3", "--holdout", "1", "--size", "40x30", "--out", str(out), "-q"]
    assert data_gen_main(args) == 0
    return out


@pytest.fixture
def database_run(tmp_path, earlier_run):
    import shutil

    shutil.copytree(earlier_run, tmp_path / "fish")
    return {"root": tmp_path, "out": tmp_path / "fish"}


def _data_gen(w, *extra):
    from data_gen.__main__ import main as data_gen_main

    return data_gen_main(["fish", "--out", str(w["out"]), "-q", *extra])


DATA_GEN_CASES = {
    "another --size and --seed (the user's case)": (
        ["--count", "2", "--size", "32x24", "--seed", "4"],
        ["fish_000.json", "--size 40x30", "--size 32x24", "--overwrite", "replace", "mixed"],
    ),
    "another --holdout split": (
        ["--count", "3", "--size", "40x30"],
        ["holdout/fish_002", "not among this run's", "--overwrite"],
    ),
    "fewer instances": (
        ["--count", "2", "--holdout", "1", "--size", "40x30"],
        ["16 of its files are not among this run's", "fish_001.json", "--overwrite"],
    ),
}


@pytest.mark.parametrize("case", sorted(DATA_GEN_CASES))
def test_data_gen_refuses_an_earlier_run_at_other_settings(database_run, capsys, case):
    extra, words = DATA_GEN_CASES[case]
    before = snapshot(database_run["root"])
    code = _data_gen(database_run, *extra)
    message = capsys.readouterr().err
    assert code == 2, message
    for word in words:
        assert word in message, message
    assert_unchanged(database_run, before)


def test_data_gen_refuses_stale_meshes_and_overwrite_replaces_the_run_whole(database_run, capsys):
    """An earlier run with --meshes: a run without is refused (its meshes/ would stay);
    with --overwrite the folder is the new run's alone."""
    from data_gen.dataset import planned_files

    out = database_run["out"]
    (out / "meshes").mkdir()
    (out / "meshes" / "fish_000.glb").write_bytes(b"an earlier run's mesh")
    before = snapshot(database_run["root"])
    assert _data_gen(database_run, "--count", "3", "--holdout", "1", "--size", "40x30") == 2
    assert "meshes/fish_000.glb" in capsys.readouterr().err
    assert_unchanged(database_run, before)
    code = _data_gen(database_run, "--count", "2", "--size", "32x24", "--overwrite")
    assert code == 0
    files = sorted(p.relative_to(out) for p in out.rglob("*") if p.is_file())
    assert files == sorted(planned_files("fish", 2))
    sizes = {tuple(json.loads((out / f"fish_00{i}.json").read_text())["size"]) for i in (0, 1)}
    assert sizes == {(32, 24)}


def test_data_gen_memory_refusal_blames_count_when_count_is_the_cause(tmp_path, capsys):
    from data_gen.__main__ import main as data_gen_main

    code = data_gen_main(["fish", "--count", "100000000", "--size", "40x30", "--out",
                          str(tmp_path / "new"), "-q"])  # fmt: skip
    message = capsys.readouterr().err
    assert code == 2 and "--count 100000000" in message and "smaller --count" in message, message
    assert not (tmp_path / "new").exists()


# -- meshes: non-finite vertices and UVs refused by name, never dropped -----------------------


def _bad_mesh(w, kind: str) -> Path:
    """A damaged mesh file in root/bad/ (its folder is part of the snapshot)."""
    folder = w["root"] / "bad"
    folder.mkdir(exist_ok=True)
    sphere = trimesh.creation.icosphere(subdivisions=3)
    if kind in ("nan.ply", "nan.obj", "inf.ply"):
        vertices = sphere.vertices.copy()
        if kind == "inf.ply":
            vertices[3] = np.inf
        else:
            vertices[::7] = np.nan  # the user's case: every 7th vertex
        trimesh.Trimesh(vertices, sphere.faces, process=False).export(folder / kind)
    elif kind == "nan_uv.glb":
        uv = sphere.vertices[:, :2] / 2 + 0.5
        uv[5] = np.nan
        export_textured(textured_mesh(sphere.vertices, sphere.faces, uv, np.ones((8, 8, 3))),
                        folder / kind)  # fmt: skip
    elif kind == "line.glb":  # zero-area faces (every vertex on a line) and NaN UVs
        vertices = np.stack([np.linspace(0, 1, 6), np.zeros(6), np.zeros(6)], axis=1)
        faces = np.array([[0, 1, 2], [1, 2, 3], [2, 3, 4], [3, 4, 5]])
        uv = np.full((6, 2), np.nan)
        export_textured(textured_mesh(vertices, faces, uv, np.ones((8, 8, 3))), folder / kind)
    return folder / kind


MESH_FILE_CASES = {
    "NaN vertices (every 7th), PLY": ("nan.ply", ["nan.ply", "92 of 642 vertices", "477 of 1280"]),
    "NaN vertices (every 7th), OBJ": ("nan.obj", ["nan.obj", "vertices are NaN or infinite"]),
    "one infinite vertex": ("inf.ply", ["inf.ply", "1 of 642 vertices", "touching 5 of 1280"]),
    "NaN UVs": ("nan_uv.glb", ["nan_uv.glb", "UV coordinates are NaN"]),
    "zero-area faces and NaN UVs": ("line.glb", ["line.glb", "UV coordinates are NaN"]),
}


@pytest.mark.parametrize("case", sorted(MESH_FILE_CASES))
def test_non_finite_meshes_are_refused_by_name(fish, capsys, no_work, case):
    kind, words = MESH_FILE_CASES[case]
    source = _bad_mesh(fish, kind)
    argv = ["synthesize", str(source), "--db", str(fish["db"] / "meshes"), "-q", "--view=front",
            "-o", str(fish["root"] / "out.glb")]  # fmt: skip
    run_refused(fish, capsys, argv, words)


def test_faces_without_area_are_refused(tmp_path):
    from imagemap.scene import load_mesh

    vertices = np.stack([np.linspace(0, 1, 6), np.zeros(6), np.zeros(6)], axis=1)
    faces = np.array([[0, 1, 2], [1, 2, 3], [2, 3, 4], [3, 4, 5]])
    trimesh.Trimesh(vertices, faces, process=False).export(tmp_path / "line.ply")
    with pytest.raises(InputError, match=r"line\.ply: its 4 faces have no area"):
        load_mesh(tmp_path / "line.ply")


def test_the_bake_size_of_nan_uvs_is_an_input_error():
    """texture_size_for (the mesh route's memory guard) on NaN UVs: an InputError, which
    the guard takes as "no usable UVs", not a ValueError traceback."""
    from imagemap.scene.bake import texture_size_for

    mesh = trimesh.creation.icosphere(subdivisions=1)
    mesh.visual = trimesh.visual.TextureVisuals(uv=np.full((len(mesh.vertices), 2), np.nan))
    with pytest.raises(InputError, match="NaN"):
        texture_size_for(mesh, 0.01)


def _nan_uv_ball():
    mesh = ball()
    mesh.visual.uv[4] = np.nan
    return mesh


@pytest.mark.parametrize(
    "mesh, kwargs, words",
    [
        (ball, {"texture_size": 64.5}, "texture_size: expected an integer"),
        (ball, {"texture_size": True}, "texture_size: expected an integer"),
        (ball, {"uv_space": "yes"}, "uv_space: expected True, False"),
        (ball, {"views": 5}, "views: expected"),
        (_nan_uv_ball, {}, "mesh: 1 of 162 UV coordinates are NaN"),
    ],
)
def test_colorize_mesh_refuses_what_it_took_as_it_came(blob_database, mesh, kwargs, words):
    with pytest.raises(InputError, match=words):
        imagemap.mesh.colorize.colorize_mesh(mesh(), blob_database, **kwargs)


def test_views_name_the_number_at_fault():
    from imagemap.scene.views import parse_views

    with pytest.raises(InputError, match="azimuth 'nan'"):
        parse_views("nan,0")
    with pytest.raises(InputError, match="elevation 'inf'"):
        parse_views("0,inf")


def test_a_tiny_mesh_is_seen_as_its_unit_size_copy():
    """A mesh 1e-6 units across rendered "nothing visible" (trimesh dropped its triangles
    as degenerate): it is cast at unit size and seen as the same mesh is."""
    from imagemap.scene.views import render_mesh

    sphere = trimesh.creation.icosphere(subdivisions=2)
    tiny = sphere.copy()
    tiny.vertices *= 1e-6
    seen, reference = render_mesh(tiny, "front", (40, 30)), render_mesh(sphere, "front", (40, 30))
    assert seen.mask.sum() == reference.mask.sum() > 400
    np.testing.assert_array_equal(seen.depth, reference.depth)
    np.testing.assert_allclose(seen.z[seen.mask], reference.z[seen.mask] * 1e-6, rtol=1e-9)


# -- smaller: a batch's orphaned output, constant PBR maps --------------------------------------


def test_resume_redoes_an_output_whose_manifest_was_deleted(fish, capsys):
    """The batch report records each output's SHA-256: an output whose manifest is gone is
    still the batch's while it has that content (resume redoes it; it was refused, and
    --force did not help); changed since, it is a user's file and stays refused."""
    inputs = fish["root"] / "in"
    inputs.mkdir()
    (inputs / "a_depth.png").write_bytes((fish["holdout"] / "q_depth.png").read_bytes())
    out = fish["root"] / "out"
    argv = ["batch", str(inputs), "--db", str(fish["db"]), "-o", str(out), "-q"]
    assert cli(argv, capsys)[0] == 0
    (out / ".imagemap-done" / "a_depth.png.json").unlink()
    code, message = cli(argv, capsys)
    assert code == 0, message
    assert (out / ".imagemap-done" / "a_depth.png.json").is_file()
    (out / ".imagemap-done" / "a_depth.png.json").unlink()
    (out / "a_image.png").write_bytes(b"the user's own picture now")
    run_refused(fish, capsys, argv, ["a_image.png", "no earlier run"])


def test_no_constant_pbr_map_is_written_for_examples_without_one(fish, capsys):
    """The database has a roughness map, the examples chosen have none (blob_1 has, but
    it is the query itself and is left out): no out_roughness.png of the neutral 0.6
    everywhere (written without a word before), and a note says so."""
    for name in ("blob_0", "blob_2", "blob_3", "blob_4"):
        (fish["db"] / f"{name}_roughness.png").unlink()
    out = fish["root"] / "out.png"
    argv = _depths(fish, "q", extra=["-o", str(out)])
    argv.remove("-q")
    code, message = cli(argv, capsys)
    assert code == 0, message
    assert out.is_file() and not (fish["root"] / "out_roughness.png").exists()
    assert "no roughness map written beside" in message and "have none" in message
