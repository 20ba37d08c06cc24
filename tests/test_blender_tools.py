"""The Blender add-on's parts that need no Blender (issue #46 item 5): progress lines,
the object's transform, the preset from the database, the subprocess cancelled."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest

from imagemap.blender import addon_tools
from imagemap.blender.addon_tools import (
    CommandRun,
    database_class,
    database_preset,
    is_mirrored,
    local_from_world,
    parse_progress,
    remove_folder,
)
from imagemap.cli import PRESET_NAMES
from imagemap.progress import step_line


def test_the_addon_knows_imagemaps_presets():
    assert tuple(addon_tools.PRESET_NAMES) == tuple(PRESET_NAMES)


def test_progress_lines_read_back_as_written():
    for step, total in [(1, 1), (1, 4), (3, 4), (4, 4)]:
        line = f"imagemap: {step_line(step, total, 'synthesizing view 90,0')}\n"
        found = parse_progress(line)
        assert found is not None
        assert (found.step, found.total, found.text) == (step, total, "synthesizing view 90,0")
        assert found.fraction == pytest.approx((step - 1) / total)
    for other in [
        "imagemap: views chosen by coverage: 0,0; 180,0",
        "imagemap: [0/4] before the first",
        "imagemap: [5/4] past the last",
        "[1/4] no prefix",
        "",
    ]:
        assert parse_progress(other) is None, other
    with pytest.raises(ValueError, match="step 5 of 4"):
        step_line(5, 4, "x")


def test_world_matrix_round_trip_and_mirrors():
    rng = np.random.default_rng(0)
    points = rng.normal(size=(50, 3))
    for scale in [(1.5, 0.5, 0.6), (-1.0, 2.0, 1.0)]:
        angle = 0.7
        rotation = np.array(
            [[np.cos(angle), -np.sin(angle), 0], [np.sin(angle), np.cos(angle), 0], [0, 0, 1]]
        )
        world = np.eye(4)
        world[:3, :3] = rotation @ np.diag(scale)
        world[:3, 3] = (2.0, -1.0, 0.5)
        sent = points @ world[:3, :3].T + world[:3, 3]
        # The scale is in what is sent: the extent along the object's x axis is 1.5x.
        local = local_from_world(world)
        back = sent @ local[:3, :3].T + local[:3, 3]
        np.testing.assert_allclose(back, points, atol=1e-12)
        assert is_mirrored(world) == (np.prod(scale) < 0)
    with pytest.raises(ValueError, match="flat"):
        local_from_world(np.diag([1.0, 0.0, 1.0, 1.0]))
    with pytest.raises(ValueError, match="affine"):
        local_from_world(np.ones((4, 4)))
    with pytest.raises(ValueError, match="4x4"):
        local_from_world(np.eye(3))


def test_preset_from_the_database_records_then_names(tmp_path):
    meshes = tmp_path / "meshes"
    meshes.mkdir()
    for name in ("fish_000.glb", "fish_001.glb", "shell-2.glb"):
        (meshes / name).write_bytes(b"")
    assert database_class(str(meshes)) == "fish"
    assert database_preset(str(meshes)) == "fish"
    pairs = tmp_path / "pairs"
    pairs.mkdir()
    for index in range(3):
        (pairs / f"thing_{index}_depth.png").write_bytes(b"")
        (pairs / f"thing_{index}_image.png").write_bytes(b"")
        (pairs / f"thing_{index}.json").write_text(json.dumps({"class": "humans"}))
    (pairs / "thing_9_depth.png").write_bytes(b"")
    (pairs / "thing_9.json").write_text("not json")  # the name tells: "thing"
    assert database_class(str(pairs)) == "humans"
    assert database_preset(str(pairs)) == "humans"
    vases = tmp_path / "vases"
    vases.mkdir()
    (vases / "vase_01.obj").write_bytes(b"")
    assert database_class(str(vases)) == "vase" and database_preset(str(vases)) is None
    empty = tmp_path / "empty"
    empty.mkdir()
    assert database_class(str(empty)) is None
    with pytest.raises(ValueError, match="not found"):
        database_class(str(tmp_path / "missing"))


CHILD = textwrap.dedent(
    """
    import signal, sys, time
    if "--stubborn" in sys.argv:
        signal.signal(signal.SIGTERM, signal.SIG_IGN)  # a child deaf to SIGTERM
    print("imagemap: views chosen by coverage: 0,0", file=sys.stderr, flush=True)
    print("imagemap: [2/4] synthesizing view 180,0", file=sys.stderr, flush=True)
    time.sleep(120)
    """
)


def wait_for(condition, seconds: float = 20.0) -> None:
    end = time.monotonic() + seconds
    while not condition():
        assert time.monotonic() < end, "timed out"
        time.sleep(0.02)


@pytest.mark.parametrize("stubborn", [False, True])
def test_cancel_ends_the_command_and_its_folder_goes(tmp_path, monkeypatch, stubborn):
    monkeypatch.setattr(addon_tools, "TERMINATE_SECONDS", 0.5)
    folder = tmp_path / "imagemap-blender-x"
    folder.mkdir()
    (folder / "0_query.glb").write_bytes(b"partial")
    command = [sys.executable, "-c", CHILD, *(["--stubborn"] if stubborn else [])]
    run = CommandRun(command)
    wait_for(lambda: run.poll() is None and run.progress is not None)
    assert run.fraction == pytest.approx(0.25)
    assert run.last == "synthesizing view 180,0 (2/4)"
    assert run.log[0] == "imagemap: views chosen by coverage: 0,0"
    started = time.monotonic()
    run.cancel()
    assert run.process.poll() is not None  # ended, not left running
    assert time.monotonic() - started < 10
    remove_folder(str(folder))
    assert not folder.exists()
    remove_folder(str(folder))  # gone already: nothing to do, no error


def test_a_finished_command_gives_its_code_and_every_line(tmp_path):
    child = "import sys; print('imagemap: [1/1] done', file=sys.stderr); sys.exit(3)"
    run = CommandRun([sys.executable, "-c", child])
    assert run.wait() == 3
    assert run.log == ["imagemap: [1/1] done"] and run.fraction == 0.0
    run.cancel()  # ended already: nothing to do


def test_commandrun_passes_its_command_to_popen():
    seen = {}

    class FakeProcess:
        stderr = None

        def __init__(self, command, **options):
            seen["command"], seen["options"] = command, options

        def poll(self):
            return 0

    run = CommandRun(["imagemap", "synthesize", "q.glb"], popen=FakeProcess)
    assert seen["command"] == ["imagemap", "synthesize", "q.glb"]
    assert seen["options"]["stderr"] == subprocess.PIPE
    assert run.poll() == 0 and run.last == "starting"
