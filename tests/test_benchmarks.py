"""The benchmark script's plumbing at tiny sizes: rows, figures, JSON (no timing assertions)."""

from __future__ import annotations

import contextlib
import io
import json
import math
from dataclasses import replace

import numpy as np
import pytest

from imagemap.cli import main as imagemap_main
from imagemap.cli.bench import SCRIPT, load_script
from imagemap.io import InputError

pytestmark = pytest.mark.skipif(not SCRIPT.is_file(), reason="no benchmarks/run.py checkout")


@pytest.fixture(scope="module")
def bench():
    return load_script()


# The whole quick run (the tests marked slow below) takes about 30 s: every case, both
# backends, two fresh processes and the quality group. CI runs a smaller one (the tests
# marked ci_slow: the JIT and colorize groups, PatchMatch only, about 10 s) as its check
# that the benchmark script (and ``imagemap bench``) still works; the whole quick run is
# in the slow command.


@pytest.fixture(scope="module")
def ci_run(tmp_path_factory):
    """``imagemap bench --quick --only jit,colorize --backends patchmatch``: its report."""
    tmp = tmp_path_factory.mktemp("bench_ci")
    out = tmp / "results.json"
    with contextlib.redirect_stdout(io.StringIO()):
        code = imagemap_main(
            [
                "bench",
                "--quick",
                "--only",
                "jit,colorize",
                "--backends",
                "patchmatch",
                "--json",
                str(out),
                "--data",
                str(tmp / "data"),
            ]
        )
    assert code == 0
    return json.loads(out.read_text())


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory):
    """``imagemap bench --quick --quality``: the report and what it printed. One run for
    the rows and the quality group (each run starts with the JIT warm-up)."""
    tmp = tmp_path_factory.mktemp("bench")
    out = tmp / "results.json"
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        code = imagemap_main(
            ["bench", "--quick", "--quality", "--json", str(out), "--data", str(tmp / "data")]
        )
    assert code == 0
    return json.loads(out.read_text()), printed.getvalue()


@pytest.fixture(scope="module")
def quick_report(quick_run):
    return quick_run[0]


def test_memory_probe_sees_an_allocation(bench):
    def allocate():
        block = np.ones(64 * 1024 * 1024 // 8)  # 64 MB, touched
        return float(block.sum())

    _, figures = bench.measure(allocate)
    assert figures["seconds"] > 0
    assert figures["traced_peak_mb"] >= 63
    if figures["rss_method"].startswith("VmHWM"):
        assert figures["rss_delta_mb"] >= 50
    assert figures["rss_peak_mb"] >= figures["rss_delta_mb"]


@pytest.mark.ci_slow
def test_ci_run_has_its_rows_with_stages_and_a_report(bench, ci_run):
    rows = ci_run["rows"]
    assert {(r["case"], r["backend"]) for r in rows} == {
        ("first call (JIT / cache load) 40x30", "patchmatch"),
        ("second call 40x30", "patchmatch"),
        ("colorize 80x60", "patchmatch"),
        ("colorize 128x96", "patchmatch"),
    }
    for row in rows:
        assert row["seconds"] > 0 and row["rss_peak_mb"] > 10, row["case"]
        assert math.isfinite(row["objective"]) and row["objective"] > 0, row["case"]
        assert {"synthesize.search", "synthesize.vote", "select", "blend"} <= set(row["stages"])
        assert 0 < sum(row["stages"].values()) <= row["seconds"] * 1.01, row["case"]
    # the same 40x30 task twice in one process: the second call's map is the first's
    first, second = (r for r in rows if r["case"].endswith("40x30"))
    assert first["objective"] == second["objective"]
    text = bench.format_report(ci_run)
    assert "| colorize 128x96 | patchmatch |" in text
    assert "| synthesize.search |" in text


@pytest.mark.slow
def test_quick_run_has_every_row_with_positive_figures(quick_report):
    rows = quick_report["rows"]
    cases = {(r["case"], r["backend"]) for r in rows}
    expected = {
        ("first call (JIT / cache load) 40x30", "patchmatch"),
        ("second call 40x30", "patchmatch"),
        ("colorize 80x60", "patchmatch"),
        ("colorize 80x60", "exact"),
        ("colorize 128x96", "patchmatch"),
        ("colorize 128x96", "exact"),
        ("btf pixelwise R=0 32->64", "exact"),
        ("btf pixelwise R=2 32->64", "exact"),
        ("btf texture optimization 32->64", "patchmatch"),
        ("btf texture optimization 32->64", "exact"),
        ("imagemap synthesize 80x60 (first process)", "patchmatch"),
        ("imagemap synthesize 80x60 (second process)", "patchmatch"),
    }
    assert expected <= cases
    for row in rows:
        assert row["seconds"] > 0, row["case"]
        assert row["rss_peak_mb"] > 10, row["case"]  # a Python process with NumPy at least
        if row["group"] != "cli":
            assert row["traced_peak_mb"] > 0, row["case"]
            assert row["rss_delta_mb"] >= 0, row["case"]
    for row in rows:
        if row["group"] in ("colorize", "jit"):
            assert math.isfinite(row["objective"]) and row["objective"] > 0
            inside = {"synthesize.search", "synthesize.vote", "synthesize.pca"}
            assert inside | {"select", "bands", "collapse", "blend"} <= set(row["stages"])
            assert 0 < sum(row["stages"].values()) <= row["seconds"] * 1.01
        if row["group"] == "btf":
            assert 0 < row["image_error_pct"] < 100


@pytest.mark.slow
def test_quick_run_exact_is_no_worse_than_patchmatch(quick_report):
    # Exact search finds the best window of each query: its final target value is
    # at most the approximate one (up to EM taking a different path, hence the slack).
    by = {(r["case"], r["backend"]): r for r in quick_report["rows"]}
    exact = by[("colorize 128x96", "exact")]["objective"]
    approximate = by[("colorize 128x96", "patchmatch")]["objective"]
    assert exact <= approximate * 1.05


@pytest.mark.slow
def test_quick_run_report_names_the_machine_and_breaks_down_stages(bench, quick_report):
    assert quick_report["machine"]["cores"] >= 1
    assert quick_report["machine"]["memory_gb"] > 0
    text = bench.format_report(quick_report)
    assert "| colorize 128x96 | patchmatch |" in text
    assert "Stages of colorize 128x96 (patchmatch)" in text
    assert "| synthesize.search |" in text


@pytest.mark.slow
def test_imagemap_bench_quality(quick_run):
    report, printed = quick_run
    quality = report["quality"]
    assert quality["objects"] == 4
    assert 0 < quality["ciede2000"] < 100
    assert "mean CIEDE2000" in printed


def test_unknown_group_is_an_input_error(bench, tmp_path):
    args = bench.build_parser().parse_args(["--only", "colourise", "--json", str(tmp_path / "x")])
    with pytest.raises(InputError, match="--only"):
        bench.run(args)
    assert not (tmp_path / "x").exists()


@pytest.mark.slow
def test_scaling_curves_have_time_and_memory_per_point(bench, tmp_path):
    settings = replace(bench.QUICK, scaling_sizes=(64,), scaling_m=(1,), scaling_database=(10,))
    rows = bench.run_scaling(tmp_path / "data", settings, trace=False)
    cases = [r["case"] for r in rows]
    assert cases == [
        "pixels 64x64 (m = 2, fresh process)",
        "examples m = 1 (64x64, fresh process)",
        "selection, database of 10 (200x150)",
    ]
    for row in rows:
        assert row["seconds"] > 0 and row["rss_peak_mb"] > 10, row
    assert rows[-1]["per_query_seconds"] > 0 and rows[-1]["database_size"] == 10


def test_the_ebsynth_side_by_side_stops_before_any_work_without_ebsynth(tmp_path, monkeypatch):
    import runpy

    monkeypatch.delenv("EBSYNTH", raising=False)
    script = SCRIPT.parent / "ebsynth_side_by_side.py"
    side_by_side = runpy.run_path(str(script), run_name="side_by_side")
    out = tmp_path / "out"
    argv = [
        "--sizes",
        "40x30",
        "--reps",
        "1",
        "--out",
        str(out),
        "--json",
        str(tmp_path / "r.json"),
    ]
    assert side_by_side["main"](argv) == 2
    assert side_by_side["main"]([*argv, "--ebsynth", str(tmp_path / "nothing")]) == 2
    assert not out.exists() and not (tmp_path / "r.json").exists()
