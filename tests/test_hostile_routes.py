"""Hostile and faulty input on the mesh, batch, Dask and data_gen routes (issue #35).

The house style of tests/test_hostile.py: every refused case asserts the exit code, a
message naming the file or option, and the SHA-256 of every file under the test folder
before and after (no input or earlier output changed, nothing new written); no synthesis
may start before the refusal. Then the behaviour that replaced each silent or crashing
case: depth units, a query found in its database, resume by content, the output lock,
workers that end with their batch, relative paths on a Dask cluster, and property tests
that drive random shapes through the whole pipeline.
"""

from __future__ import annotations

import fcntl
import http.server
import json
import logging
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import trimesh
from conftest import PALETTE, blob, painted
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_hostile import (
    assert_unchanged,
    cli,
    depth16,
    run_refused,
    snapshot,
    write_database,
)

import imagemap
import imagemap.batch.cluster
import imagemap.batch.pool
import imagemap.batch.work
import imagemap.depth.pipeline
import imagemap.mesh
import imagemap.mesh.colorize
from imagemap.batch import BatchOptions, run_batch
from imagemap.database import Database, Example, check_database
from imagemap.depth import completion, units
from imagemap.depth.budget import memory_check
from imagemap.io import InputError, read_depth, read_image, write_image
from imagemap.scene import FRONT, export_textured, textured_mesh

REPO = Path(__file__).resolve().parents[1]


def ball(stretch=(1.5, 1.0, 0.8), subdivisions=2):
    """A small textured ellipsoid (UVs from x, y; a two-colour texture)."""
    mesh = trimesh.creation.icosphere(subdivisions=subdivisions)
    mesh.vertices *= stretch
    uv = mesh.vertices[:, :2] / (2 * np.asarray(stretch[:2])) + 0.5
    rows, cols = np.mgrid[0:32, 0:32]
    texture = np.stack([cols / 31, np.where(rows < 16, 0.2, 0.8), np.full((32, 32), 0.4)], -1)
    return textured_mesh(mesh.vertices, mesh.faces, uv, texture)


@pytest.fixture
def world(tmp_path, tmp_path_factory, blob_database, query_blob, monkeypatch):
    """db/ (pictures and one mesh), q/ (an OBJ with its MTL and photo texture, an OBJ whose
    MTL is shared and whose texture is in a subfolder, a depth query with its truth),
    holdout/ (two depth queries with truths), meshes/ (a GLB and an OBJ query)."""
    monkeypatch.setenv("IMAGEMAP_CACHE", str(tmp_path_factory.mktemp("cache")))
    root = tmp_path
    db = root / "db"
    db.mkdir()
    write_database(db, blob_database)
    export_textured(ball((1.4, 1.0, 0.7)), db / "m0.glb")
    q = root / "q"
    export_textured(ball(), q / "f46.obj")  # f46.obj, f46.mtl, f46.png (the "photo")
    write_image(q / "f46_image.png", np.full((12, 16, 3), 0.3))  # its held-out truth
    (q / "textures").mkdir()
    export_textured(ball((1.2, 1.0, 1.0)), q / "textures" / "skin.obj")
    (q / "textures" / "skin.obj").unlink()
    (q / "shared.mtl").write_text("newmtl skin\nmap_Kd textures/skin.png\n")
    (q / "textures" / "skin.mtl").unlink()
    text = (q / "f46.obj").read_text().replace("mtllib f46.mtl", "mtllib shared.mtl")
    (q / "g.obj").write_text(text.replace("usemtl f46", "usemtl skin"))
    depth, truth = query_blob
    write_image(q / "q_depth.png", depth16(depth))
    write_image(q / "q_image.png", truth)
    holdout = root / "holdout"
    holdout.mkdir()
    for name, example in (("a", blob_database[1]), ("b", blob_database[3])):
        write_image(holdout / f"{name}_depth.png", depth16(example.depth))
        write_image(holdout / f"{name}_image.png", example.image)
    meshes = root / "meshes"
    export_textured(ball((1.3, 1.0, 0.9)), meshes / "m1.glb")
    export_textured(ball((1.5, 1.1, 0.8)), meshes / "m2.obj")
    (root / "afile").write_text("keep me")
    (root / "adir").mkdir()
    photos = root / "photos"
    photos.mkdir()
    (photos / "holiday.png").write_bytes(b"\x89PNG a user's photo")
    return {"root": root, "db": db, "q": q, "holdout": holdout, "meshes": meshes}


def mesh_synth(w, source, *extra):
    return ["synthesize", str(source), "--db", str(w["db"]), "-q", "--views", "front", *extra]


# -- the mesh route: nothing lost -------------------------------------------------------------

MESH_CASES = {
    "-o is the input OBJ": (
        lambda w: mesh_synth(w, w["q"] / "f46.obj", "-o", str(w["q"] / "f46.obj")),
        ["f46.obj", "input mesh"],
    ),
    "-o's material is the MTL the input reads": (
        lambda w: mesh_synth(w, w["q"] / "g.obj", "-o", str(w["q"] / "shared.obj")),
        ["shared.mtl", "g.obj reads"],
    ),
    "-o's texture is the photo the input reads": (
        lambda w: mesh_synth(w, w["q"] / "g.obj", "-o", str(w["q"] / "textures" / "skin.obj")),
        ["skin.png", "g.obj reads"],
    ),
    "-o into the database folder": (
        lambda w: mesh_synth(w, w["q"] / "f46.obj", "-o", str(w["db"] / "f56.obj")),
        ["f56.obj", "database"],
    ),
    "-o is a database example's mesh": (
        lambda w: mesh_synth(w, w["q"] / "f46.obj", "-o", str(w["db"] / "m0.glb")),
        ["m0.glb", "database"],
    ),
    "-o's texture is a depth map (a user's file)": (
        lambda w: mesh_synth(w, w["q"] / "f46.obj", "-o", str(w["holdout"] / "a_depth.obj")),
        ["a_depth.png", "not part of"],
    ),
    "-o's texture is a user's photo": (
        lambda w: mesh_synth(w, w["q"] / "f46.obj", "-o", str(w["root"] / "photos/holiday.obj")),
        ["holiday.png", "not part of"],
    ),
    "-o is the mesh's held-out truth": (
        lambda w: mesh_synth(w, w["q"] / "f46.obj", "-o", str(w["q"] / "f46_image.png")),
        ["f46_image.png", "held-out truth", "--overwrite"],
    ),
    "--provenance is a database file": (
        lambda w: mesh_synth(
            w,
            w["meshes"] / "m1.glb",
            "-o",
            str(w["root"] / "m.glb"),
            "--provenance",
            str(w["db"] / "blob_1_labels.png"),
        ),
        ["blob_1_labels.png", "--provenance"],
    ),
    "--report is a database file": (
        lambda w: mesh_synth(
            w,
            w["meshes"] / "m1.glb",
            "-o",
            str(w["root"] / "m.glb"),
            "--report",
            str(w["db"] / "blob_0.json"),
        ),
        ["blob_0.json", "--report"],
    ),
    "-o x.png --provenance x.png": (
        lambda w: mesh_synth(
            w,
            w["meshes"] / "m1.glb",
            "-o",
            str(w["root"] / "x.png"),
            "--provenance",
            str(w["root"] / "x.png"),
        ),
        ["x.png", "same file"],
    ),
    "--provenance is the OBJ's texture": (
        lambda w: mesh_synth(
            w,
            w["meshes"] / "m1.glb",
            "-o",
            str(w["root"] / "m.obj"),
            "--provenance",
            str(w["root"] / "m.png"),
        ),
        ["m.png", "same file"],
    ),
    "--preview is the OBJ's texture": (
        lambda w: mesh_synth(
            w,
            w["meshes"] / "m1.glb",
            "-o",
            str(w["root"] / "m.obj"),
            "--preview",
            str(w["root"] / "m.png"),
        ),
        ["m.png", "same file"],
    ),
    "-o under a file": (
        lambda w: mesh_synth(w, w["meshes"] / "m1.glb", "-o", str(w["root"] / "afile" / "m.glb")),
        ["afile", "not a directory"],
    ),
    "--provenance under a file": (
        lambda w: mesh_synth(
            w,
            w["meshes"] / "m1.glb",
            "-o",
            str(w["root"] / "m.glb"),
            "--provenance",
            str(w["root"] / "afile/p.png"),
        ),
        ["afile", "--provenance"],
    ),
    "-o without a mesh suffix": (
        lambda w: mesh_synth(w, w["meshes"] / "m1.glb", "-o", str(w["root"] / "adir")),
        ["adir", ".glb"],
    ),
    "-o .jpg": (
        lambda w: mesh_synth(w, w["meshes"] / "m1.glb", "-o", str(w["root"] / "m.jpg")),
        ["m.jpg", ".png"],
    ),
    "a mesh and a depth map together": (
        lambda w: [
            "synthesize",
            str(w["meshes"] / "m1.glb"),
            str(w["q"] / "q_depth.png"),
            "--db",
            str(w["db"]),
            "-o",
            str(w["root"] / "x.glb"),
        ],
        ["imagemap batch"],
    ),
}


@pytest.mark.parametrize("case", sorted(MESH_CASES))
def test_mesh_route_replaces_no_input(world, capsys, no_work, case):
    build, words = MESH_CASES[case]
    run_refused(world, capsys, build(world), words)


def test_mesh_route_writes_the_obj_set_and_may_replace_its_own(world, capsys):
    """The OBJ, its MTL and texture are written as one set (no staging folder left), and a
    rerun may replace a set it wrote (the main output exists)."""
    out = world["root"] / "out" / "m.obj"
    argv = mesh_synth(world, world["meshes"] / "m1.glb", "--size", "24x18", "--texture-size", "32")
    assert cli([*argv, "-o", str(out)], capsys)[0] == 0
    assert sorted(p.name for p in out.parent.iterdir()) == ["m.mtl", "m.obj", "m.png"]
    code, message = cli([*argv, "-o", str(out)], capsys)
    assert code == 0, message
    assert sorted(p.name for p in out.parent.iterdir()) == ["m.mtl", "m.obj", "m.png"]


# -- options that do not apply, or conflict ---------------------------------------------------

OPTION_CASES = {
    **{
        f"{flag} on a depth map": (["synthesize", "DEPTH", flag, value], [flag, "depth map"])
        for flag, value in (
            ("--size", "300x200"),
            ("--view", "front"),
            ("--views", "front,back"),
            ("--texture-size", "256"),
            ("--units", "mm"),
            ("--scale", "2"),
        )
    },
    "--view beside --views": (
        ["synthesize", "MESH", "--views", "front", "--view", "back"],
        ["--view", "--views"],
    ),
    "--views beside --view": (
        ["synthesize", "MESH", "--view", "back", "--views", "front"],
        ["--view", "--views"],
    ),
    "--view ''": (["synthesize", "MESH", "--view="], ["--view", "no view"]),
    "--views ''": (["synthesize", "MESH", "--views="], ["--views", "no view"]),
    "--examples ''": (["synthesize", "DEPTH", "--examples="], ["--examples", "no example"]),
    "--exclude ''": (["synthesize", "DEPTH", "--exclude="], ["--exclude", "no example"]),
    "--examples twice": (
        ["synthesize", "DEPTH", "--examples", "blob_1,blob_1"],
        ["--examples", "twice"],
    ),
    "--examples also excluded": (
        ["synthesize", "DEPTH", "--examples", "blob_1", "--exclude", "blob_1"],
        ["--exclude", "blob_1"],
    ),
    "--background on a GLB": (
        ["synthesize", "MESH", "--background", "white"],
        ["--background", ".png"],
    ),
    "--size of 20000x20000": (
        ["synthesize", "MESH", "--size", "20000x20000"],
        ["--size", "memory"],
    ),
    "--texture-size 100000": (
        ["synthesize", "MESH", "--texture-size", "100000"],
        ["--texture-size", "memory"],
    ),
    "batch --view beside --views": (
        ["batch", "--views", "front", "--view", "back"],
        ["--view", "--views"],
    ),
    "batch --views ''": (["batch", "--views="], ["--views"]),
    "batch --workers x": (["batch", "--workers", "x"], ["--workers"]),
    "batch --scheduler http://": (
        ["batch", "--scheduler", "http://localhost:8786"],
        ["--scheduler"],
    ),
    "batch --format ply": (["batch", "--format", "ply"], ["--format"]),
    # #45: accepted together, the last one silently won.
    "batch --scheduler with --workers": (
        ["batch", "--workers", "2", "--scheduler", "tcp://127.0.0.1:8786"],
        ["--scheduler", "not allowed with", "--workers"],
    ),
    "--uv-space with --no-uv-space": (
        ["synthesize", "MESH", "--uv-space", "--no-uv-space"],
        ["--no-uv-space", "not allowed with", "--uv-space"],
    ),
}


@pytest.mark.parametrize("case", sorted(OPTION_CASES))
def test_options_that_do_not_apply_or_conflict_are_refused(world, capsys, no_work, case):
    argv, words = OPTION_CASES[case]
    command, rest = argv[0], argv[1:]
    out = str(world["root"] / ("out" if command == "batch" else "m.glb"))
    if command == "batch":
        argv = ["batch", str(world["holdout"]), "--db", str(world["db"]), "-o", out, "-q", *rest]
    else:
        source = world["q"] / "q_depth.png" if rest[0] == "DEPTH" else world["meshes"] / "m1.glb"
        out = str(world["root"] / ("m.png" if rest[0] == "DEPTH" else "m.glb"))
        argv = ["synthesize", str(source), "--db", str(world["db"]), "-o", out, "-q", *rest[1:]]
    run_refused(world, capsys, argv, words)


def test_every_mesh_option_is_refused_on_depth_input(world, capsys, no_work):
    """The refusal follows the mesh options as declared: a new one is covered at once."""
    from imagemap.cli.synthesize import MESH_FLAGS

    cli(["synthesize", "--help"], capsys)  # the parser is built
    assert {"view", "views", "size", "texture_size"} <= set(MESH_FLAGS)


# -- the batch route: nothing lost ------------------------------------------------------------


def _batch(w, inputs, out, *extra):
    return ["batch", str(inputs), "--db", str(w["db"]), "-o", str(out), "-q", *extra]


def _shared_name_inputs(w):
    folder = w["root"] / "shared"
    export_textured(ball(), folder / "x_image.obj")
    (folder / "x_image.png").rename(folder / "x_skin.png")  # the OBJ's texture elsewhere
    mtl = folder / "x_image.mtl"
    mtl.write_text(mtl.read_text().replace("x_image.png", "x_skin.png"))
    write_image(folder / "x_depth.png", depth16(read_depth(w["holdout"] / "a_depth.png")))
    return folder


def _two_of_one_name(w):
    folder = w["root"] / "twice"
    folder.mkdir()
    write_image(folder / "a_depth.png", depth16(read_depth(w["holdout"] / "a_depth.png")))
    np.save(folder / "a_depth.npy", read_depth(w["holdout"] / "a_depth.png"))
    return folder


def _user_file_at(w, name):
    out = w["root"] / "out"
    out.mkdir()
    (out / name).write_bytes(b"a user's file")
    return out


BATCH_CASES = {
    "-o is its own mesh folder (--format obj)": (
        lambda w: _batch(w, w["meshes"], w["meshes"], "--format", "obj"),
        ["m2.obj", "input mesh"],
    ),
    "-o is the holdout folder (truths beside)": (
        lambda w: _batch(w, w["holdout"], w["holdout"]),
        ["a_image.png", "held-out truth"],
    ),
    "-o is the database": (lambda w: _batch(w, w["holdout"], w["db"]), ["database"]),
    "-o is the database, meshes": (lambda w: _batch(w, w["meshes"], w["db"]), ["database"]),
    "a depth and a mesh write one file": (
        lambda w: _batch(w, _shared_name_inputs(w), w["root"] / "out", "--format", "obj"),
        ["x_depth.png", "x_image.obj", "x_image.png"],
    ),
    "two depth maps of one name": (
        lambda w: _batch(w, _two_of_one_name(w), w["root"] / "out"),
        ["a_depth.npy", "a_depth.png", "a_image.png"],
    ),
    "-o holds a user's file at an output's name": (
        lambda w: _batch(w, w["holdout"], _user_file_at(w, "a_image.png")),
        ["a_image.png", "no earlier run"],
    ),
    "an OBJ's texture over a user's file": (
        lambda w: _batch(w, w["meshes"], _user_file_at(w, "m1.png"), "--format", "obj"),
        ["m1.png", "no earlier run"],
    ),
    "-o is a file": (lambda w: _batch(w, w["holdout"], w["root"] / "afile"), ["afile"]),
    "-o under a file": (lambda w: _batch(w, w["holdout"], w["root"] / "afile" / "o"), ["afile"]),
    "--db is a file": (
        lambda w: [
            "batch",
            str(w["holdout"]),
            "--db",
            str(w["root"] / "afile"),
            "-o",
            str(w["root"] / "o"),
        ],
        ["afile", "not a directory"],
    ),
    "input folder missing": (
        lambda w: _batch(w, w["root"] / "nowhere", w["root"] / "o"),
        ["nowhere"],
    ),
    "input folder is a file": (
        lambda w: _batch(w, w["root"] / "afile", w["root"] / "o"),
        ["afile"],
    ),
}


@pytest.mark.parametrize("case", sorted(BATCH_CASES))
def test_batch_replaces_no_input(world, capsys, no_work, case):
    build, words = BATCH_CASES[case]
    argv = build(world)
    run_refused(world, capsys, argv, words)


def test_batch_into_a_locked_folder_stops(world, capsys, no_work):
    out = world["root"] / "out"
    (out / ".imagemap-done").mkdir(parents=True)
    with open(out / ".imagemap-done" / "lock", "a+") as held:
        fcntl.flock(held, fcntl.LOCK_EX | fcntl.LOCK_NB)
        held.write("4242\n")
        held.flush()
        run_refused(world, capsys, _batch(world, world["holdout"], out), ["another batch", "4242"])


@pytest.fixture
def silent_port():
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(8)
    accepted = []

    def accept():
        while True:
            try:
                accepted.append(server.accept()[0])
            except OSError:
                return

    threading.Thread(target=accept, daemon=True).start()
    yield server.getsockname()[1]
    server.close()


@pytest.fixture
def http_port():
    class Quiet(http.server.SimpleHTTPRequestHandler):
        def log_message(self, *args):
            pass

    # Threads per request: a client that never finishes its request holds one thread,
    # not the server's loop (which shutdown() waits for).
    httpd = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Quiet)
    httpd.daemon_threads = True
    threading.Thread(target=httpd.serve_forever, daemon=True).start()
    yield httpd.server_address[1]
    httpd.shutdown()
    httpd.server_close()


@pytest.fixture
def babbling_port():
    """A port that answers every connection with bytes that are not Dask's protocol (a
    Dask client read them as a frame length and asked for 3.07 EiB: MemoryError)."""
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(8)

    def accept():
        while True:
            try:
                connection = server.accept()[0]
                connection.sendall(b"\xff" * 64)
            except OSError:
                return

    threading.Thread(target=accept, daemon=True).start()
    yield server.getsockname()[1]
    server.close()


def test_a_scheduler_that_speaks_another_protocol_is_named_so(
    world, capsys, no_work, monkeypatch, babbling_port
):
    pytest.importorskip("distributed")
    monkeypatch.setattr(imagemap.batch.cluster, "CONNECT_SECONDS", 1.0)
    argv = _batch(world, world["holdout"], world["root"] / "out")
    argv += ["--scheduler", f"tcp://127.0.0.1:{babbling_port}"]
    run_refused(world, capsys, argv, ["--scheduler", "does not speak Dask's protocol"])


@pytest.mark.parametrize("server", ["silent_port", "http_port"])
def test_a_scheduler_that_does_not_answer_is_refused_in_time(
    world, capsys, no_work, monkeypatch, request, server
):
    pytest.importorskip("distributed")
    port = request.getfixturevalue(server)
    monkeypatch.setattr(imagemap.batch.cluster, "CONNECT_SECONDS", 1.0)
    start = time.monotonic()
    argv = _batch(world, world["holdout"], world["root"] / "out")
    run_refused(world, capsys, [*argv, "--scheduler", f"tcp://127.0.0.1:{port}"], ["--scheduler"])
    assert time.monotonic() - start < 15


# -- data_gen ----------------------------------------------------------------------------------

DATA_GEN_CASES = {
    "--out an existing database": (lambda w: ["fish", "--out", str(w["db"])], ["blob_0"]),
    "--out a user's folder": (
        lambda w: ["fish", "--out", str(w["root"] / "photos")],
        ["holiday.png"],
    ),
    "--out another class's run": (lambda w: ["busts", "--out", str(w["holdout"])], ["a_depth.png"]),
    "--size beyond memory": (
        lambda w: ["fish", "--size", "100000x100000", "--out", str(w["root"] / "new")],
        ["--size", "memory"],
    ),
}


@pytest.mark.parametrize("case", sorted(DATA_GEN_CASES))
def test_data_gen_out_and_size_are_checked_first(world, capsys, case, monkeypatch):
    from data_gen import dataset
    from data_gen.__main__ import main as data_gen_main

    def refuse(*args, **kwargs):
        raise AssertionError("data_gen started before the refusal")

    monkeypatch.setattr(dataset, "write_class", refuse)
    monkeypatch.setattr("data_gen.__main__.write_class", refuse)
    build, words = DATA_GEN_CASES[case]
    before = snapshot(world["root"])
    code = data_gen_main([*build(world), "--count", "2", "-q"])
    message = capsys.readouterr().err
    assert code == 2, message
    for word in words:
        assert word in message, message
    assert_unchanged(world, before)


def test_data_gen_may_remake_its_own_folder(tmp_path):
    from data_gen.__main__ import main as data_gen_main

    args = ["fish", "--count", "1", "--size", "32x24", "--out", str(tmp_path / "fish"), "-q"]
    assert data_gen_main(args) == 0
    assert data_gen_main(args) == 0


# -- the API: InputError naming the argument, never a raw error --------------------------------


def test_database_lookups_and_opening_name_the_problem(blob_database):
    for key in (99, -6):
        with pytest.raises(InputError, match=f"no example at position {key}"):
            blob_database[key]
    for key in (1.5, None, True):
        with pytest.raises(InputError, match="by name or position"):
            blob_database[key]
    assert blob_database[-1].name == "blob_4"
    for bad in (None, 3, ""):
        with pytest.raises(InputError, match="from_directory"):
            Database.from_directory(bad)


@pytest.mark.parametrize(
    "kwargs, words",
    [
        ({"seed": -1}, "seed"),
        ({"size": (5, 5)}, "size"),
        ({"size": "200x150"}, "size"),
        ({"views": [1]}, "views"),
        ({"views": (FRONT, FRONT)}, "twice"),
        ({"views": ()}, "views"),
        ({"background": (2.0, 0, 0)}, "background"),
        ({"background": (0.5, 0.5)}, "background"),
        ({"options": {"m": 0}}, "m"),
        ({"options": 3}, "options"),
        ({"texture_size": 0}, "texture_size"),
        ({"mesh_format": "ply"}, "mesh format"),
        ({"preset": "dogs"}, "preset"),
    ],
)
def test_batch_options_are_checked_when_built(kwargs, words):
    with pytest.raises(InputError, match=words):
        BatchOptions(**kwargs)


@pytest.mark.parametrize(
    "mesh, kwargs, words",
    [
        (None, {}, "got NoneType"),
        ("scene", {}, "got Scene"),
        ("points", {}, "got PointCloud"),
        ("ball", {"views": [1]}, "views"),
        ("ball", {"views": "sideways"}, "sideways"),
        ("ball", {"size": (5, 5)}, "size"),
        ("ball", {"size": "200x150"}, "size"),
        ("ball", {"texture_size": -1}, "texture_size"),
    ],
)
def test_colorize_mesh_arguments_name_the_problem(blob_database, mesh, kwargs, words):
    shapes = {
        "ball": ball(),
        "scene": trimesh.Scene([ball()]),
        "points": trimesh.PointCloud(ball().vertices),
    }
    with pytest.raises(InputError, match=words):
        imagemap.mesh.colorize.colorize_mesh(shapes.get(mesh), blob_database, **kwargs)


@pytest.mark.parametrize("mesh", [None, "a.glb", trimesh.Scene()])
def test_export_textured_of_no_mesh_is_an_input_error(tmp_path, mesh):
    with pytest.raises(InputError, match="export_textured: mesh"):
        export_textured(mesh, tmp_path / "x.glb")
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize(
    "kwargs, words",
    [
        ({"workers": "2"}, "workers"),
        ({"workers": 0}, "workers"),
        ({"workers": 1.5}, "workers"),
        ({"scheduler": 3}, "scheduler"),
        ({"options": "fish"}, "options"),
    ],
)
def test_run_batch_arguments_are_checked(world, kwargs, words):
    before = snapshot(world["root"])
    with pytest.raises(InputError, match=words):
        run_batch(world["holdout"], world["db"], world["root"] / "out", **kwargs)
    with pytest.raises(InputError, match="database"):
        run_batch(world["holdout"], None, world["root"] / "out")
    assert_unchanged(world, before)


# -- a query found in its database -------------------------------------------------------------


def test_a_query_that_is_an_example_is_left_out_with_a_notice(blob_database, caplog):
    query = blob_database[2].depth
    with caplog.at_level(logging.WARNING, logger="imagemap"):
        result = imagemap.colorize(query, blob_database, "fish", seed=0)
    assert "blob_2" not in result.example_names
    assert "left out" in caplog.text and "blob_2" in caplog.text
    stage = next(record for record in result.stages if record.name == "select")
    assert "blob_2" in stage.changed
    # Not the example's own map back, byte for byte.
    assert not np.array_equal(result.image, blob_database[2].image * result.mask[..., None])
    with pytest.raises(InputError, match="blob_2.*query itself"):
        imagemap.colorize(query, blob_database, "fish", examples=["blob_2", "blob_1"])
    with pytest.raises(InputError, match="only example"):
        imagemap.colorize(query, Database([blob_database[2]]), "fish")
    with units.query_in_database():  # on purpose (a test of the measures with a twin)
        kept = imagemap.colorize(query, blob_database, "fish", seed=0)
    assert kept.example_names[0] == "blob_2"


def test_cli_query_from_the_database_named_is_refused(world, capsys):
    query = world["db"] / "blob_0_depth.png"
    argv = ["synthesize", str(query), "--db", str(world["db"]), "-q", "--preset", "fish"]
    # Refused by the pipeline's first stage, before the engine: nothing written.
    run_refused(
        world,
        capsys,
        [*argv, "-o", str(world["root"] / "m.png"), "--examples", "blob_0"],
        ["blob_0", "query itself"],
    )
    code, message = cli([*argv, "-o", str(world["root"] / "m.png")], capsys)
    assert code == 0, message  # chosen automatically: left out, and the map is made


# -- depth units do not matter -----------------------------------------------------------------


def test_depth_units_do_not_matter(blob_database, query_blob, tmp_path):
    """#42, item 3: the same relief as float at any positive factor (1e-6 to 1e6, and the
    issue's 0.5 to 2) gives the same examples and the same map (within 2 of 255 mean
    |RGB| over the object: #42's bound), and so does its 16-bit PNG."""
    depth = query_blob[0]
    database = Database(list(blob_database)[1:])
    unit = imagemap.colorize(depth, database, "fish", seed=0)
    mask = unit.mask

    def difference(result) -> float:
        return float(np.abs(result.image - unit.image)[mask].mean() * 255)

    for scale in (1e-6, 1e-3, 0.5, 0.7, 1.3, 1.6, 2.0, 1000.0, 1e6):
        np.save(tmp_path / "s_depth.npy", (depth * scale).astype(np.float64))
        scaled = imagemap.colorize(read_depth(tmp_path / "s_depth.npy"), database, "fish")
        assert scaled.example_names == unit.example_names, scale
        assert difference(scaled) <= 2.0, scale
    write_image(tmp_path / "q_depth.png", depth16(depth))
    png = imagemap.colorize(read_depth(tmp_path / "q_depth.png"), database, "fish", seed=0)
    assert png.example_names == unit.example_names
    assert difference(png) <= 2.0


def test_the_pose_is_said(blob_database, query_blob):
    result = imagemap.colorize(query_blob[0][:, ::-1] * 1e-3, blob_database, "fish", seed=0)
    said = next(r.changed for r in result.stages if r.name == "pose")
    assert "turned" in said and "scaled" in said


# -- no traceback from the finishing stages ----------------------------------------------------


def test_a_displaced_copy_outside_the_object_leaves_the_map_as_it_was():
    """_undouble met a feature's displaced copy wholly outside the object (a face against
    fish): a raw ValueError from _within on no pixels. Now nothing is recopied."""
    exemplar = np.full((80, 80, 3), 0.5, np.float32)
    exemplar[10:18, 10:18, 0] = 0.1  # an 8 x 8 feature
    labels, n = completion.small_features(exemplar, np.ones((80, 80), bool))
    assert n == 1
    yy, xx = np.mgrid[:60, :60]
    source = np.stack([np.zeros((60, 60), int), np.full((60, 60), 30), np.full((60, 60), 30)], -1)
    main_copy = (yy >= 30) & (yy < 36) & (xx >= 30) & (xx < 38)  # 6 of its 8 rows
    displaced = (yy >= 36) & (yy < 42) & (xx >= 30) & (xx < 36)  # rows 2-7 again, below
    source[main_copy] = np.stack([0 * yy, yy - 20, xx - 20], -1)[main_copy]
    source[displaced] = np.stack([0 * yy, yy - 24, xx - 20], -1)[displaced]
    outside = yy >= 36  # the displaced copy lies outside the object
    ones = np.ones((80, 80), bool)
    out, done = completion.complete_features([exemplar], source, [(labels, n)], ~outside, [ones])
    assert done == 0 and np.array_equal(out, source)
    assert not completion._within(np.array([], int), np.array([], int), (5, 5))


def _shape(kind: int, h: int, w: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[:h, :w].astype(np.float32)
    cy, cx = rng.uniform(0.3, 0.7) * h, rng.uniform(0.3, 0.7) * w
    ry, rx = rng.uniform(3, h / 2), rng.uniform(3, w / 2)
    inside = (np.abs(yy - cy) < ry) & (np.abs(xx - cx) < rx)
    if kind == 0:  # a dome
        depth = np.sqrt(np.clip(1 - ((yy - cy) / ry) ** 2 - ((xx - cx) / rx) ** 2, 0, None))
    elif kind == 1:  # a flat square
        depth = inside * rng.uniform(0.01, 1.0)
    elif kind == 2:  # a tilted box
        depth = inside * (0.3 + 0.5 * xx / w)
    elif kind == 3:  # a ring
        r = np.hypot((yy - cy) / ry, (xx - cx) / rx)
        depth = ((r > 0.5) & (r < 1)) * 0.5
    elif kind == 4:  # a thin bar
        depth = (np.abs(yy - cy) < 1.5) * 0.5
    else:  # speckle
        depth = np.where(rng.random((h, w)) < 0.5, rng.random((h, w)), 0)
    return (depth * rng.choice([1e-3, 1.0, 250.0])).astype(np.float32)


@settings(
    max_examples=8, deadline=None, suppress_health_check=[HealthCheck.too_slow], derandomize=True
)
@given(
    kind=st.integers(0, 5),
    h=st.integers(8, 32),
    w=st.integers(8, 32),
    seed=st.integers(0, 3),
    preset=st.sampled_from(["fish", "busts", "humans"]),
    examples=st.integers(1, 3),
)
def test_random_shapes_go_through_the_whole_pipeline(kind, h, w, seed, preset, examples):
    """Any shape against any small database: a map or an InputError, never a traceback."""
    depth = _shape(kind, h, w, seed)
    database = Database(
        [
            Example.from_arrays(f"e{i}", d, painted(d, PALETTE))
            for i, d in enumerate(
                blob(centre=(20 + 3 * i, 30), radii=(12 + i, 20), bumps=0.03, seed=i)
                for i in range(examples)
            )
        ]
    )
    try:
        with memory_check(False):
            result = imagemap.colorize(depth, database, preset, seed=seed, m=1)
    except InputError:
        return
    assert result.image.shape == (h, w, 3) and np.all(np.isfinite(result.image))
    assert result.image.min() >= 0 and result.image.max() <= 1


# -- batches: resume, interrupt, lock, workers, Dask -------------------------------------------


def test_ctrl_c_writes_the_report_and_says_how_to_resume(world, capsys, monkeypatch):
    real = imagemap.batch.work.process_job
    calls = []

    def second_interrupts(job, *args):
        calls.append(job)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return real(job, *args)

    monkeypatch.setattr(imagemap.batch.work, "process_job", second_interrupts)
    out = world["root"] / "out"
    code, message = cli(_batch(world, world["holdout"], out, "--preset", "fish"), capsys)
    assert code == 130
    assert "run the same command again to resume" in message
    report = json.loads((out / "batch_report.json").read_text())
    assert report["interrupted"] is True and report["done"] == 1
    monkeypatch.setattr(imagemap.batch.work, "process_job", real)
    code, message = cli(_batch(world, world["holdout"], out, "--preset", "fish"), capsys)
    report = json.loads((out / "batch_report.json").read_text())
    assert code == 0 and (report["done"], report["skipped"]) == (1, 1), message


def test_workers_beyond_the_cores_are_capped_and_said(world, caplog):
    one = world["root"] / "one"
    one.mkdir()
    (one / "a_depth.png").write_bytes((world["holdout"] / "a_depth.png").read_bytes())
    with caplog.at_level(logging.WARNING, logger="imagemap"):
        summary = run_batch(
            one, world["db"], world["root"] / "out", BatchOptions(preset="fish"), workers=10_000
        )
    assert summary.done == 1 and "--workers 10000" in caplog.text and "cores" in caplog.text
    assert imagemap.batch.pool._usable_workers(10_000, 50) == min(os.cpu_count() or 1, 50)


def test_the_lock_is_released_when_a_batch_ends(world):
    out = world["root"] / "out"
    options = BatchOptions(preset="fish")
    assert run_batch(world["holdout"], world["db"], out, options).done == 2
    assert run_batch(world["holdout"], world["db"], out, options).skipped == 2  # not locked


def test_pool_workers_end_when_the_batch_is_killed(world):
    """kill -9 of a batch: its spawned pool workers end too (within a few seconds)."""
    psutil = pytest.importorskip("psutil")
    slow = world["root"] / "slow"
    slow.mkdir()
    depth = np.kron(read_depth(world["holdout"] / "a_depth.png"), np.ones((2, 2), np.float32))
    for i in range(6):
        np.save(slow / f"s{i}_depth.npy", depth)
    out = world["root"] / "out"
    command = [sys.executable, "-m", "imagemap", "batch", str(slow), "--db", str(world["db"])]
    command += ["-o", str(out), "--workers", "2", "--preset", "fish", "-q"]
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    process = subprocess.Popen(command, env=env)
    parent = psutil.Process(process.pid)
    done = out / ".imagemap-done"
    deadline = time.monotonic() + 90
    children: list = []
    both_working = False
    # Killed once both workers hold a job (each has written its .started record): without
    # the parent-death handling both stayed alive (checked against a copy without it).
    while time.monotonic() < deadline and process.poll() is None:
        children = [
            c for c in parent.children(recursive=True) if "spawn_main" in " ".join(c.cmdline())
        ]
        if len(children) >= 2 and done.is_dir() and len(list(done.glob("*.started"))) >= 2:
            both_working = True
            break
        time.sleep(0.05)
    assert both_working, "the two workers were not seen at work"
    process.send_signal(signal.SIGKILL)
    process.wait()
    gone, alive = psutil.wait_procs(children, timeout=10)
    assert not alive, f"workers left alive: {[p.pid for p in alive]}"


def test_relative_paths_on_a_dask_cluster_give_the_local_bytes(world, monkeypatch):
    """Workers with their own working directory: paths are absolute before they travel."""
    distributed = pytest.importorskip("distributed")
    options = BatchOptions(preset="fish")
    local = world["root"] / "local"
    run_batch(world["holdout"], world["db"], local, options)
    monkeypatch.chdir(world["root"])
    with (
        distributed.LocalCluster(
            n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None
        ) as cluster,
        distributed.Client(cluster) as client,
    ):
        client.run(os.chdir, "/")  # the workers elsewhere, as on another machine
        summary = run_batch("holdout", "db", "dask_out", options, scheduler=client)
    assert (summary.done, summary.failed) == (2, 0), summary.records
    for name in ("a_image.png", "b_image.png"):
        assert (world["root"] / "dask_out" / name).read_bytes() == (local / name).read_bytes()


# -- the database's own checks ------------------------------------------------------------------


def test_db_check_reports_a_one_pixel_example(world, capsys):
    depth = np.zeros((20, 20), np.uint16)
    depth[10, 10] = 40000
    write_image(world["db"] / "dot_depth.png", depth)
    write_image(world["db"] / "dot_image.png", np.full((20, 20, 3), 0.5))
    rows, problems = check_database(world["db"])
    assert any("dot_depth.png" in p and "1 pixel" in p for p in problems)
    code, message = cli(["db", "check", str(world["db"])], capsys)
    assert code == 1 and "dot_depth.png" in message


def test_a_fully_transparent_image_map_is_refused(world, capsys):
    rgba = np.zeros((48, 64, 4), np.uint8)
    rgba[..., :3] = 200  # hidden colours, alpha 0 everywhere
    write_image(world["db"] / "blob_0_image.png", rgba)
    with pytest.raises(InputError, match="blob_0_image.png.*transparent"):
        read_image(world["db"] / "blob_0_image.png")
    rows, problems = check_database(world["db"])
    assert any("blob_0_image.png" in p for p in problems)


def test_an_unwritable_cache_is_said_at_the_door(world, capsys, no_work, monkeypatch):
    monkeypatch.setenv("IMAGEMAP_CACHE", str(world["root"] / "afile"))
    argv = mesh_synth(world, world["meshes"] / "m1.glb", "-o", str(world["root"] / "m.glb"))
    run_refused(world, capsys, argv, ["IMAGEMAP_CACHE", "afile"])
    run_refused(
        world, capsys, _batch(world, world["meshes"], world["root"] / "o"), ["IMAGEMAP_CACHE"]
    )


# -- evaluate ------------------------------------------------------------------------------------


def test_evaluate_methods_twice_is_refused(world, capsys):
    argv = ["evaluate", str(world["db"]), "--out", str(world["root"] / "r"), "-q"]
    run_refused(
        world, capsys, [*argv, "--methods", "full,copy_nearest,full"], ["--methods", "full"]
    )


def test_no_bootstrap_interval_from_two_objects():
    """From 2 objects the summary printed intervals and "supported" differences: now n/a."""
    from test_evaluation import _scored_objects

    from imagemap.report import MIN_BOOTSTRAP_OBJECTS, bootstrap_intervals

    two = _scored_objects([True, False], [0.4, 0.9], [1, 0])
    for row in (bootstrap_intervals(two), bootstrap_intervals(two, relative_to="full")):
        assert all(np.isnan(v).all() for v in row["fish"]["full"].values())
    enough = _scored_objects([True, False] * 2, [0.4, 0.9] * 2, [1, 0] * 2)
    assert len(enough.objects) == MIN_BOOTSTRAP_OBJECTS
    low, high = bootstrap_intervals(enough)["fish"]["full"]["ssim"]
    assert 0.4 <= low < high <= 0.9


def test_ulimit_v_is_a_refusal_not_a_memory_error(world):
    """Under ``ulimit -v`` the guard counts the address space the engine will map: a
    2000x1500 query at 900 MB was let through and died with a MemoryError traceback."""
    import resource

    depth = np.zeros((1500, 2000), np.float32)
    yy, xx = np.mgrid[:1500, :2000]
    depth[((yy - 750) / 600.0) ** 2 + ((xx - 1000) / 800.0) ** 2 < 1] = 0.6
    np.save(world["root"] / "big_depth.npy", depth)
    limit = 900 * 2**20

    def cap():
        resource.setrlimit(resource.RLIMIT_AS, (limit, resource.getrlimit(resource.RLIMIT_AS)[1]))

    command = [sys.executable, "-m", "imagemap", "synthesize", str(world["root"] / "big_depth.npy")]
    command += ["--db", str(world["db"]), "-o", str(world["root"] / "big.png"), "-q"]
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    done = subprocess.run(command, env=env, preexec_fn=cap, capture_output=True, text=True)
    assert done.returncode == 2, done.stderr
    assert "big_depth.npy" in done.stderr and "memory" in done.stderr
    assert "Traceback" not in done.stderr and not (world["root"] / "big.png").exists()
