"""Options declared once reach the pipeline on every route, and the pipeline's own record."""

from __future__ import annotations

import json
from dataclasses import fields

import numpy as np
import pytest
import trimesh

import imagemap.depth.pipeline
from imagemap.cli import main
from imagemap.depth.config import OPTIONS, PRESETS, DepthConfig, resolve_config
from imagemap.io import InputError, write_image


def write_db(root, database):
    root.mkdir(parents=True, exist_ok=True)
    for example in database:
        write_image(
            root / f"{example.name}_depth.png", np.round(example.depth * 65535).astype(np.uint16)
        )
        write_image(root / f"{example.name}_image.png", example.image)
    return root


#: A value other than the busts preset's for every option (switches: the flag's value).
_DEFAULT = PRESETS["busts"].flat()


def _other_value(option):
    if option.kind == "switch_on":
        return True
    if option.kind == "switch_off":
        return False
    if option.kind == "choice":
        default = _DEFAULT.get(option.setting)
        return next(c for c in option.choices if c != default)
    return {"positive_int": 1, "non_negative_float": 0.7, "fraction": 0.55}[option.kind]


#: Every option set away from its default at once (the named finish tried on its own).
ALL = {o.name: _other_value(o) for o in OPTIONS if o.setting is not None}
ALL["vote"] = "mode"  # the copied vote inside the EM: away from the default "copy"


def _flags(options):
    argv = []
    for option in OPTIONS:
        if option.name not in options:
            continue
        value = options[option.name]
        if option.kind.startswith("switch"):
            argv.append(option.flag)
        else:
            argv += [option.flag, str(value)]
    return argv


def _assert_reached(config: DepthConfig, options: dict) -> None:
    flat = config.flat()
    expected = resolve_config("busts", **options).flat()
    for name in options:
        setting = next(o.setting for o in OPTIONS if o.name == name)
        if setting is not None:
            assert flat[setting] == expected[setting], name
    for key, value in expected.items():
        if key != "patch_sizes":  # sized for the object before the stages
            assert flat[key] == value, key


@pytest.fixture
def recorded(monkeypatch):
    """The configurations the pipeline ran with, in call order."""
    seen = []
    original = imagemap.depth.pipeline.run_pipeline

    def recording(state, config, *args, **kwargs):
        seen.append(config)
        return original(state, config, *args, **kwargs)

    monkeypatch.setattr(imagemap.depth.pipeline, "run_pipeline", recording)
    return seen


@pytest.fixture
def files(tmp_path, blob_database, query_blob):
    db = write_db(tmp_path / "db", blob_database)
    depth, _ = query_blob
    inputs = tmp_path / "inputs"
    inputs.mkdir()
    query = inputs / "query_depth.png"
    write_image(query, np.round(depth * 65535).astype(np.uint16))
    mesh = trimesh.creation.icosphere(subdivisions=2)
    mesh.apply_scale((1.6, 1.0, 0.6))
    meshes = tmp_path / "meshes"
    meshes.mkdir()
    mesh.export(meshes / "ball.glb")
    return db, query, inputs, meshes / "ball.glb"


def _route(route, files, tmp_path, argv):
    db, query, inputs, mesh = files
    common = ["--db", str(db), "--preset", "busts", "-q", *argv]
    if route == "depth":
        return main(["synthesize", str(query), "-o", str(tmp_path / "m.png"), *common])
    if route == "mesh":
        out = str(tmp_path / "m.glb")
        return main(["synthesize", str(mesh), "-o", out, "--size", "64x48", *common])
    if route == "batch":
        out = str(tmp_path / "batch")
        return main(["batch", str(inputs), "-o", out, "--workers", "1", *common])
    if route == "dask":
        distributed = pytest.importorskip("distributed", reason="dask[distributed] not installed")
        with distributed.LocalCluster(
            n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None
        ) as cluster:
            out = str(tmp_path / "dask")
            scheduler = ["--scheduler", cluster.scheduler_address]
            return main(["batch", str(inputs), "-o", out, *scheduler, *common])
    if route == "evaluate":
        out = str(tmp_path / "report")
        argv = common[2:]  # the database is the positional argument
        return main(["evaluate", str(db), "--out", out, "--methods", "full", "--limit", "1"] + argv)
    raise AssertionError(route)


ROUTES = ["depth", "mesh", "batch", "dask", "evaluate"]


@pytest.mark.parametrize("route", ROUTES)
def test_every_option_reaches_the_pipeline(route, files, tmp_path, recorded):
    assert _route(route, files, tmp_path, _flags(ALL)) == 0
    assert recorded, "the pipeline did not run"
    for config in recorded:
        _assert_reached(config, ALL)


@pytest.mark.parametrize("route", ["depth", "mesh", "batch"])
def test_the_paper_finish_reaches_the_pipeline(route, files, tmp_path, recorded):
    assert _route(route, files, tmp_path, ["--finish", "paper", "--m", "1"]) == 0
    for config in recorded:
        assert config.finish.vote == "mean" and config.matching.appearance_pyramid == "laplacian"
        assert not config.finish.complete_features and config.selection.m == 1


def test_the_api_takes_the_same_options(blob_database, query_blob, recorded):
    depth, _ = query_blob
    imagemap.colorize(depth, blob_database, "busts", **ALL)
    _assert_reached(recorded[-1], ALL)
    with pytest.raises(InputError, match="unknown option colour"):
        imagemap.colorize(depth, blob_database, "busts", colour="red")
    with pytest.raises(InputError, match="edge_support"):
        imagemap.colorize(depth, blob_database, "busts", edge_support=1.5)


def test_a_bad_option_stops_the_cli_before_any_work(files, tmp_path, capsys, recorded):
    code = _route("depth", files, tmp_path, ["--finish", "sketch"])
    assert code == 2 and not recorded
    assert "--finish" in capsys.readouterr().err


def test_the_report_and_verbose_log_give_every_stage(files, tmp_path, caplog):
    db, query, _, _ = files
    report = tmp_path / "r.json"
    out = tmp_path / "m.png"
    argv = ["synthesize", str(query), "--db", str(db), "-o", str(out), "--report", str(report)]
    with caplog.at_level("INFO", logger="imagemap"):
        assert main([*argv, "-v"]) == 0
    stages = json.loads(report.read_text())["stages"]
    names = [stage["name"] for stage in stages]
    assert names == [stage.name for stage in imagemap.depth.pipeline.STAGES]
    by_name = {stage["name"]: stage for stage in stages}
    assert by_name["register"]["changed"] != "off"  # on in the preset
    assert by_name["select"]["changed"] and by_name["synthesize"]["seconds"] > 0
    logged = [r.getMessage() for r in caplog.records if r.getMessage().startswith("stage ")]
    assert [line.split(":")[0] for line in logged] == [
        f"stage {s['name']}" for s in stages if s["changed"] != "off"
    ]


def test_a_stage_left_out_changes_the_map_and_a_copy_of_the_stages_does_not(
    blob_database, query_blob
):
    """STAGES is what colorize runs: the same tuple gives the same bytes; without the
    blend the copy's seams stay hard."""
    from imagemap.core.stages import run_pipeline
    from imagemap.depth.guides import sized_config
    from imagemap.depth.pipeline import STAGES, State

    depth, _ = query_blob
    config = sized_config(resolve_config("busts"), depth > 0)

    def run(stages):
        state = State(depth=depth, database=blob_database, seed=0, names=None)

        return run_pipeline(state, config, stages)[0].image

    full = imagemap.colorize(depth, blob_database, "busts", seed=0).image
    assert run(tuple(STAGES)).tobytes() == full.tobytes()
    unblended = run(tuple(stage for stage in STAGES if stage.name != "blend"))
    assert unblended.tobytes() != full.tobytes()


def test_every_setting_has_one_name_and_one_group():
    """Field names are unique across the groups (replace_fields finds each by its name)
    and flat() gives every field of every group."""
    config = DepthConfig()
    names = [f.name for group in fields(config) for f in fields(getattr(config, group.name))]
    assert len(names) == len(set(names))
    assert list(config.flat()) == names
    changed = config.replace_fields(rim=3, work_size=32.0, pose_turn_tolerance=5.0, edge_floor=0.1)
    assert (changed.completion.rim, changed.registration.work_size) == (3, 32.0)
    assert (changed.selection.pose_turn_tolerance, changed.finish.edge_floor) == (5.0, 0.1)
    with pytest.raises(InputError, match="control_grids"):
        config.replace_fields(control_grids=(3, 5))
    with pytest.raises(InputError, match="partial_share"):
        config.replace_fields(partial_share=1.5)


def test_the_internal_thresholds_reach_the_stages(blob_database, query_blob, monkeypatch):
    """The registration's, the completion's, the pose's and the blend's thresholds are
    handed from the configuration to the functions the stages call (not read from
    module constants)."""
    import imagemap.depth.finish
    import imagemap.depth.selection

    pipeline = imagemap.depth.pipeline
    seen: dict = {}

    def spy(module, name, key):
        original = getattr(module, name)

        def recording(*args, **kwargs):
            seen.setdefault(key, []).append((args, kwargs))
            return original(*args, **kwargs)

        monkeypatch.setattr(module, name, recording)

    spy(pipeline, "register_with_detail", "register")
    spy(pipeline.completion, "small_features", "small_features")
    spy(pipeline.completion, "complete_features", "complete_features")
    spy(imagemap.depth.finish, "seamless_copy", "seamless_copy")
    spy(imagemap.depth.selection, "find_poses", "find_poses")
    config = resolve_config("busts").replace_fields(
        work_size=48.0, rim_agreement=0.06, mirror=False, edge_contrast=2.5
    )
    depth, _ = query_blob
    imagemap.colorize(depth, blob_database, config)
    assert all(kw["registration"] is config.registration for _, kw in seen["register"])
    assert all(kw["completion"] is config.completion for _, kw in seen["small_features"])
    assert all(kw["completion"] is config.completion for _, kw in seen["complete_features"])
    assert seen["seamless_copy"][0][1]["edge_contrast"] == 2.5
    assert seen["seamless_copy"][0][1]["edge_floor"] == config.finish.edge_floor
    assert seen["find_poses"] and all(kw["mirrored"] is False for _, kw in seen["find_poses"])
