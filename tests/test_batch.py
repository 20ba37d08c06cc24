"""Batches on a local pool and a real Dask LocalCluster; resumption; the mesh CLI paths."""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest

from data_gen import CLASSES
from data_gen.__main__ import main as data_gen_main
from data_gen.core import make_instance
from data_gen.dataset import instance_mesh
from imagemap.batch import BatchOptions, plan_jobs, run_batch
from imagemap.cli import main
from imagemap.io import InputError, read_image, write_image
from imagemap.scene import check_textured, export_textured, load_mesh, render_textured

SIZE = (60, 45)
#: In centimetres (issue #46: --units was accepted and ignored by the batch).
# The views path (the registered one has its own tests: tests/test_registered.py).
OPTIONS = BatchOptions(preset="fish", size=SIZE, texture_size=64, scale=0.01, registered=False)
#: The same options as imagemap synthesize's command line.
SINGLE = ["--preset", "fish", "--size", "60x45", "--texture-size", "64", "--view", "front"]
SINGLE += ["--units", "cm", "--no-register", "-q"]


def alpha_masked(mesh):
    """``mesh`` with its texture's left half cut by alpha, double-sided, cut-off 0.4 (an
    artist's alpha-masked fins)."""
    from PIL import Image
    from trimesh.visual.material import PBRMaterial

    from imagemap.scene.views import texture_image

    rgba = np.dstack([texture_image(mesh), np.ones(texture_image(mesh).shape[:2])])
    rgba[:, : rgba.shape[1] // 3, 3] = 0.0
    mesh.visual = type(mesh.visual)(
        uv=mesh.visual.uv,
        material=PBRMaterial(
            baseColorTexture=Image.fromarray(np.round(rgba * 255).astype(np.uint8), "RGBA"),
            alphaMode="MASK",
            alphaCutoff=0.4,
            doubleSided=True,
            roughnessFactor=0.35,
        ),
    )
    return mesh


@pytest.fixture(scope="module")
def fish(tmp_path_factory):
    """A database of 3 textured fish meshes; queries: 2 meshes (one alpha-masked) and 1
    depth map. Three objects: two workers, a stop or a kill mid-way and the rest to do."""
    root = tmp_path_factory.mktemp("fish")
    previous = os.environ.get("IMAGEMAP_CACHE")
    os.environ["IMAGEMAP_CACHE"] = str(root / "cache")
    for index in (0, 1, 2, 4, 5):  # xatlas charts each mesh (1 s): no more than needed
        folder = root / ("db" if index < 3 else "queries")
        mesh = instance_mesh(CLASSES["fish"], index, seed=0, texture_size=128)
        if index == 5:
            mesh = alpha_masked(mesh)
        export_textured(mesh, folder / f"fish_{index:03d}.glb")
    depth = make_instance(CLASSES["fish"], 6, seed=0, size=SIZE).depth
    write_image(root / "queries" / "fish_006_depth.png", depth, bits=16)
    yield root
    if previous is None:
        os.environ.pop("IMAGEMAP_CACHE", None)
    else:
        os.environ["IMAGEMAP_CACHE"] = previous


#: The mesh queries of the ``fish`` fixture (with the depth map fish_006: 3 objects).
MESH_QUERIES = ("fish_004", "fish_005")
OBJECTS = len(MESH_QUERIES) + 1


def assert_valid_outputs(out: Path) -> None:
    for name in MESH_QUERIES:
        assert check_textured(out / f"{name}.glb"), name
    rgba = read_image(out / "fish_006_image.png")
    assert rgba.shape == (45, 60, 3) and rgba.max() > 0.1
    assert not [p for p in out.iterdir() if p.name.startswith(".fish")]  # no temporaries


@pytest.fixture(scope="module")
def pool_run(fish, tmp_path_factory):
    # On a fresh clone the numba cache is empty and this is the first synthesis of the
    # run: one object in this process first compiles the kernels once (and caches them),
    # so that the two spawned workers load them rather than each compile them.
    warm = tmp_path_factory.mktemp("warm")
    (warm / "queries").mkdir()
    shutil.copy(fish / "queries" / "fish_006_depth.png", warm / "queries")
    assert run_batch(warm / "queries", fish / "db", warm / "out", OPTIONS).done == 1
    out = tmp_path_factory.mktemp("pool")
    summary = run_batch(fish / "queries", fish / "db", out, OPTIONS, workers=2)
    return out, summary


def test_local_pool_of_two_makes_every_object(pool_run):
    out, summary = pool_run
    assert (summary.done, summary.skipped, summary.failed) == (OBJECTS, 0, 0)
    assert summary.per_minute > 0
    assert_valid_outputs(out)
    report = json.loads((out / "batch_report.json").read_text())
    assert report["done"] == OBJECTS and report["objects_per_minute"] > 0
    assert {r["name"] for r in report["objects"]} == {f"fish_00{i}" for i in (4, 5, 6)}
    # The mesh queries were synthesized from the database's meshes.
    assert all(
        set(r["examples"]) <= {"fish_000", "fish_001", "fish_002"} for r in report["objects"]
    )


def test_batch_gives_the_bytes_of_the_single_command(fish, pool_run, tmp_path):
    """Issue #46: the batch made a base colour only (roughness 0.6), OPAQUE single-sided
    meshes from alpha-masked ones, no PBR maps for depth maps, and ignored --units. Every
    file of the pool's run equals imagemap synthesize's with the same options (the Dask
    run equals the pool's: the test below)."""
    from imagemap.scene.files import material_of

    pool_out, _ = pool_run
    db = str(fish / "db")
    for name in MESH_QUERIES:
        single = tmp_path / f"{name}.glb"
        query = str(fish / "queries" / f"{name}.glb")
        assert main(["synthesize", query, "--db", db, "-o", str(single), *SINGLE]) == 0
        assert single.read_bytes() == (pool_out / f"{name}.glb").read_bytes(), name
    masked = load_mesh(pool_out / "fish_005.glb")
    material = material_of(masked)
    assert (material.alpha_mode, material.alpha_cutoff, material.double_sided) == (
        "MASK",
        pytest.approx(0.4),
        True,
    )
    assert masked.visual.material.metallicRoughnessTexture is not None  # the examples' maps
    extent = np.ptp(masked.vertices, axis=0).max()
    source = np.ptp(load_mesh(fish / "queries" / "fish_005.glb").vertices, axis=0).max()
    assert extent == pytest.approx(source * 0.01)  # --units cm
    depth = str(fish / "queries" / "fish_006_depth.png")
    single = tmp_path / "fish_006_image.png"
    assert main(["synthesize", depth, "--db", db, "-o", str(single), "--preset", "fish", "-q"]) == 0
    assert single.read_bytes() == (pool_out / "fish_006_image.png").read_bytes()
    maps = sorted(p.name for p in tmp_path.glob("fish_006_image_*.png"))
    assert maps == ["fish_006_image_roughness.png"]  # the mesh examples' roughness
    for path in maps:
        kind = path.removeprefix("fish_006_image_")
        assert (tmp_path / path).read_bytes() == (pool_out / f"fish_006_{kind}").read_bytes()


def test_dask_local_cluster_of_two_workers_gives_the_same_bytes(fish, pool_run, tmp_path):
    distributed = pytest.importorskip("distributed", reason="dask[distributed] not installed")
    pool_out, _ = pool_run
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=False, dashboard_address=None
    ) as cluster:
        assert len(cluster.workers) == 2
        summary = run_batch(
            fish / "queries", fish / "db", tmp_path, OPTIONS, scheduler=cluster.scheduler_address
        )
    assert (summary.done, summary.skipped, summary.failed) == (OBJECTS, 0, 0)
    assert_valid_outputs(tmp_path)
    names = (*(f"{name}.glb" for name in MESH_QUERIES), "fish_006_image.png")
    for name in (*names, "fish_006_roughness.png"):
        assert (tmp_path / name).read_bytes() == (pool_out / name).read_bytes(), name


def test_a_changed_engine_redoes_finished_objects(fish, pool_run, monkeypatch):
    # Resuming after an upgrade must not mix two engines' maps in one output folder.
    import imagemap.batch.plan
    from imagemap.batch.work import is_complete

    out, _ = pool_run
    jobs = plan_jobs(fish / "queries", out, OPTIONS)
    assert len(jobs) == OBJECTS and all(is_complete(job, OPTIONS) for job in jobs)
    monkeypatch.setattr(imagemap.batch.plan, "engine_digest", lambda: "another engine")
    assert not any(is_complete(job, OPTIONS) for job in jobs)


def test_stop_mid_batch_then_resume(fish, tmp_path):
    def stop(record):
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_batch(fish / "queries", fish / "db", tmp_path, OPTIONS, workers=2, on_result=stop)
    finished = len(list((tmp_path / ".imagemap-done").glob("*.json")))
    assert 1 <= finished < OBJECTS
    summary = run_batch(fish / "queries", fish / "db", tmp_path, OPTIONS)
    assert (summary.done, summary.skipped, summary.failed) == (OBJECTS - finished, finished, 0)
    assert_valid_outputs(tmp_path)
    # A damaged output is redone; complete ones are skipped.
    damaged = tmp_path / "fish_004.glb"
    damaged.write_bytes(damaged.read_bytes()[:100])
    summary = run_batch(fish / "queries", fish / "db", tmp_path, OPTIONS)
    assert (summary.done, summary.skipped) == (1, OBJECTS - 1)
    assert_valid_outputs(tmp_path)
    # Other options are other outputs: nothing is skipped.
    other = BatchOptions(preset="fish", size=SIZE, texture_size=64, seed=1)
    assert plan_jobs(fish / "queries", tmp_path, other)
    from imagemap.batch.work import is_complete

    assert not any(is_complete(j, other) for j in plan_jobs(fish / "queries", tmp_path, other))


def test_killed_batch_resumes_with_every_output_complete(fish, tmp_path):
    """SIGKILL mid-batch (no clean-up at all), then the same command again."""
    import signal
    import subprocess
    import sys
    import time

    out = tmp_path / "out"
    command = [sys.executable, "-m", "imagemap", "batch", str(fish / "queries")]
    command += ["--db", str(fish / "db"), "-o", str(out), "--preset", "fish"]
    command += ["--size", "60x45", "--texture-size", "64", "-q"]
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])}
    process = subprocess.Popen(command, env=env)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and process.poll() is None:
        if len(list((out / ".imagemap-done").glob("*.json"))) >= 1:
            break
        time.sleep(0.05)
    process.send_signal(signal.SIGKILL)
    process.wait()
    finished = len(list((out / ".imagemap-done").glob("*.json")))
    assert 1 <= finished < OBJECTS, "the batch must be killed mid-way"
    # As a kill leaves it, for the last object (never finished here, whatever `finished`).
    (out / ".fish_006_image.stale123.imagemap-tmp.png").write_bytes(b"half a file")
    mine = out / ".fish_005.holiday.png"  # a user's file that merely looks like one
    mine.write_bytes(b"keep me")
    assert main(command[3:]) == 0  # the same command again (in this process: no start-up)
    report = json.loads((out / "batch_report.json").read_text())
    assert (report["skipped"], report["done"]) == (finished, OBJECTS - finished)
    assert mine.read_bytes() == b"keep me"
    mine.unlink()
    assert_valid_outputs(out)


def test_a_failing_object_is_reported_and_the_rest_go_on(fish, tmp_path, caplog):
    queries = tmp_path / "queries"
    queries.mkdir()
    shutil.copy(fish / "queries" / "fish_004.glb", queries)
    (queries / "broken.glb").write_bytes(b"glTF but not really")
    summary = run_batch(queries, fish / "db", tmp_path / "out", OPTIONS)
    assert (summary.done, summary.failed) == (1, 1)
    failed = [r for r in summary.records if r["status"] == "failed"]
    assert "broken.glb" in failed[0]["error"]
    assert check_textured(tmp_path / "out" / "fish_004.glb")
    assert not (tmp_path / "out" / "broken.glb").exists()


def test_bad_batch_input_stops_at_the_door(fish, tmp_path):
    with pytest.raises(InputError, match="nowhere: input directory not found"):
        run_batch(tmp_path / "nowhere", fish / "db", tmp_path / "out", OPTIONS)
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputError, match="empty: no depth maps"):
        run_batch(tmp_path / "empty", fish / "db", tmp_path / "out", OPTIONS)
    with pytest.raises(InputError, match="workers"):
        run_batch(fish / "queries", fish / "db", tmp_path / "out", OPTIONS, workers=0)
    assert not (tmp_path / "out").exists()


def test_batch_cli_summary_and_skip(fish, tmp_path, capsys):
    queries = tmp_path / "queries"
    queries.mkdir()
    shutil.copy(fish / "queries" / "fish_005.glb", queries)
    shutil.copy(fish / "queries" / "fish_006_depth.png", queries)
    args = ["batch", str(queries), "--db", str(fish / "db"), "-o", str(tmp_path / "out")]
    args += ["--preset", "fish", "--size", "60x45", "--format", "obj"]
    assert main(args) == 0
    assert "2 done, 0 skipped, 0 failed" in capsys.readouterr().err
    assert check_textured(tmp_path / "out" / "fish_005.obj")
    assert (tmp_path / "out" / "fish_005.png").is_file()
    assert main(args) == 0
    assert "0 done, 2 skipped, 0 failed" in capsys.readouterr().err


def test_synthesize_cli_mesh_to_glb_obj_png(fish, tmp_path, capsys):
    query = str(fish / "queries" / "fish_004.glb")
    base = ["synthesize", query, "--db", str(fish / "db"), "--preset", "fish", "--size", "60x45"]
    base += ["--no-register"]  # the views path
    assert main([*base, "-o", str(tmp_path / "a.glb"), "-q"]) == 0
    assert main([*base, "-o", str(tmp_path / "b.glb"), "-q"]) == 0
    assert (tmp_path / "a.glb").read_bytes() == (tmp_path / "b.glb").read_bytes()  # same seed
    loaded = load_mesh(tmp_path / "a.glb")
    assert check_textured(tmp_path / "a.glb") and len(loaded.faces) == 10560
    views = ["--views", "front,back", "--texture-size", "64"]
    assert main([*base, *views, "-o", str(tmp_path / "c.obj"), "-q"]) == 0
    assert check_textured(tmp_path / "c.obj")
    assert main([*base, "--view", "front", "-o", str(tmp_path / "map.png"), "-q"]) == 0
    assert read_image(tmp_path / "map.png").shape == (45, 60, 3)
    depth = str(fish / "queries" / "fish_006_depth.png")
    code = main(["synthesize", depth, "--db", str(fish / "db"), "-o", str(tmp_path / "d.glb")])
    assert code == 2 and "needs a mesh input" in capsys.readouterr().err
    missing = ["synthesize", str(tmp_path / "missing.glb"), *base[2:], "-o", "e.glb"]
    code = main(missing)
    assert code == 2 and "missing.glb: mesh file not found" in capsys.readouterr().err


def test_mesh_command_writes_step_lines_the_addon_reads(fish, tmp_path, capsys):
    """Issue #46 item 5: progress within one object, on stderr whatever it is (a pipe here)."""
    from imagemap.blender.addon_tools import parse_progress

    query = str(fish / "queries" / "fish_004.glb")
    args = ["synthesize", query, "--db", str(fish / "db"), "--preset", "fish", "--size", "60x45"]
    args += ["--views", "front,back", "--texture-size", "64", "-o", str(tmp_path / "a.glb")]
    assert main([*args, "--no-register"]) == 0
    steps = [parse_progress(line) for line in capsys.readouterr().err.splitlines()]
    found = [(s.step, s.total, s.text) for s in steps if s is not None]
    assert found == [
        (1, 4, "synthesizing view 0,0"),
        (2, 4, "synthesizing view 180,0"),
        (3, 4, "baking 2 views"),
        (4, 4, "baking the examples' PBR maps"),
    ]
    assert main([*args[:-1], str(tmp_path / "b.glb"), "-q"]) == 0
    assert capsys.readouterr().err == ""  # --quiet: none


def test_data_gen_meshes_look_like_their_image_maps(tmp_path):
    from skimage.transform import resize

    out = tmp_path / "fish"
    args = ["fish", "--count", "2", "--holdout", "1", "--size", "80x60", "--meshes"]
    assert data_gen_main([*args, "--out", str(out), "-q"]) == 0
    assert check_textured(out / "meshes" / "fish_000.glb")
    assert check_textured(out / "holdout" / "meshes" / "fish_001.glb")
    truth = read_image(out / "fish_000_image.png")
    mesh = load_mesh(out / "meshes" / "fish_000.glb")
    seen = render_textured(mesh, "front", size=(80, 60), background=0.0)

    def crop(image):
        ys, xs = np.nonzero(image.sum(axis=2) > 0)
        return resize(image[ys.min() : ys.max() + 1, xs.min() : xs.max() + 1], (40, 80))

    assert np.abs(crop(seen) - crop(truth)).mean() < 0.06
    # Same seed, same mesh file (whatever the count: one object is enough to compare).
    again = tmp_path / "again"
    alone = ["fish", "--count", "1", "--size", "80x60", "--meshes"]
    assert data_gen_main([*alone, "--out", str(again), "-q"]) == 0
    first = (out / "meshes" / "fish_000.glb").read_bytes()
    assert first == (again / "meshes" / "fish_000.glb").read_bytes()


def test_resume_checks_content_not_size(fish, tmp_path):
    """An output changed at the same size (a flipped byte) is made again on resume; the
    manifest holds each output's SHA-256 and the options that made it."""
    queries = tmp_path / "queries"
    queries.mkdir()
    shutil.copy(fish / "queries" / "fish_006_depth.png", queries)
    out = tmp_path / "out"
    assert run_batch(queries, fish / "db", out, OPTIONS).done == 1
    manifest = json.loads((out / ".imagemap-done" / "fish_006_depth.png.json").read_text())
    # The image-map and the PBR map the examples have (their roughness).
    assert set(manifest["outputs"]) == {"fish_006_image.png", "fish_006_roughness.png"}
    assert len(manifest["outputs"]["fish_006_image.png"]) == 64  # SHA-256, not a size
    assert manifest["settings"]["preset"] == "fish"
    output = out / "fish_006_image.png"
    good = output.read_bytes()
    damaged = bytearray(good)
    damaged[len(damaged) // 2] ^= 0xFF
    output.write_bytes(bytes(damaged))
    assert output.stat().st_size == len(good)
    summary = run_batch(queries, fish / "db", out, OPTIONS)
    assert (summary.done, summary.skipped) == (1, 0)
    assert output.read_bytes() == good
    assert run_batch(queries, fish / "db", out, OPTIONS).skipped == 1


def test_the_engine_digest_covers_every_module_a_synthesis_runs():
    # A batch resumed after an upgrade redoes its objects when the engine's code changed
    # (batch.digests.ENGINE_MODULES): every imagemap module that the depth and mesh routes
    # and the outputs import must be in the digest, but for those that shape no byte.
    import json
    import os
    import subprocess
    import sys
    from pathlib import Path

    from imagemap.batch.digests import ENGINE_MODULES

    shapes_nothing = {"__init__", "__main__", "batch", "cli", "errors", "memory", "progress"}
    shapes_nothing |= {"validate"}
    probe = (
        "import json, sys\n"
        "import imagemap.depth.pipeline, imagemap.mesh.route, imagemap.outputs\n"
        "import imagemap.scene.examples, imagemap.mesh.register\n"
        "print(json.dumps(sorted(n for n in sys.modules if n.startswith('imagemap.'))))\n"
    )
    root = Path(__file__).resolve().parents[1]
    out = subprocess.run(
        [sys.executable, "-c", probe],
        capture_output=True,
        text=True,
        check=True,
        env={**os.environ, "PYTHONPATH": str(root)},
    ).stdout
    modules = {name.split(".")[1] for name in json.loads(out.splitlines()[-1])}
    assert modules - shapes_nothing <= set(ENGINE_MODULES)
