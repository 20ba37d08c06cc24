"""Leave-one-out evaluation: twins, baselines, the report files, the CLI."""

from __future__ import annotations

import csv
import math
import shutil
from pathlib import Path

import pytest

from data_gen.dataset import write_class
from imagemap.cli import main
from imagemap.database import Database
from imagemap.depth.config import METHODS
from imagemap.depth.units import query_in_database
from imagemap.evaluation import evaluate_object, leave_one_out, method_params
from imagemap.io import InputError
from imagemap.report import CSV_COLUMNS, check_report, summarize, write_report

#: The small generated class of the default tests: fish, 6 objects, 80x60, seed 0.
CLASS, COUNT, SIZE, SEED = "fish", 6, (80, 60), 0
#: The class the baselines are compared on: 6 fish at the size the presets are set for
#: (the paper's 200x150). At 80x60 the fish is ~30 px across, about three windows: there
#: the full method and one_pass are within noise of each other (24.6 vs 24.5 mean ΔE00).
NOMINAL_SIZE = (200, 150)


@pytest.fixture(scope="module")
def fish_dir(tmp_path_factory):
    root = tmp_path_factory.mktemp("fish")
    write_class(CLASS, root, count=COUNT, seed=SEED, size=SIZE, quiet=True)
    return root


@pytest.fixture(scope="module")
def twin_dir(fish_dir, tmp_path_factory):
    """The fish class with fish_002's mapping duplicated as fish_102."""
    root = tmp_path_factory.mktemp("twin")
    for path in fish_dir.iterdir():
        if path.is_file():
            shutil.copy(path, root / path.name)
    for suffix in ("_depth.png", "_image.png", "_labels.png", ".json"):
        shutil.copy(fish_dir / f"fish_002{suffix}", root / f"fish_102{suffix}")
    return root


def test_twin_gives_a_near_perfect_leave_one_out_and_the_metrics_say_so(twin_dir, fish_dir):
    with query_in_database():  # the twin is the query itself: kept, on purpose
        twin = evaluate_object(
            Database.from_directory(twin_dir),
            "fish_002",
            preset="fish",
            methods=("full", "copy_nearest"),
        )
    alone = evaluate_object(
        Database.from_directory(fish_dir), "fish_002", preset="fish", methods=("full",)
    )
    full = twin.results["full"]
    # The twin's depth is the query's, so it is selected first and its windows match exactly.
    assert full.examples[0] == "fish_102"
    assert full.metrics.ciede2000 < 1.5
    assert full.metrics.ssim > 0.95
    assert full.metrics.part_accuracy > 0.97
    assert full.metrics.part_transfer > 0.97
    # Pasting the twin is the truth itself.
    copy = twin.results["copy_nearest"]
    assert copy.examples == ["fish_102"]
    assert copy.metrics.ciede2000 == 0.0 and copy.metrics.part_accuracy == 1.0
    # Without the twin the same object is far from perfect: the metrics tell them apart.
    assert alone.results["full"].metrics.ciede2000 > 5 * full.metrics.ciede2000 + 5


@pytest.fixture(scope="module")
def class_evaluation(tmp_path_factory):
    root = tmp_path_factory.mktemp("fish_nominal")
    write_class(CLASS, root, count=COUNT, seed=SEED, size=NOMINAL_SIZE, quiet=True)
    return leave_one_out(
        Database.from_directory(root),
        methods=("full", "copy_nearest", "one_pass", "laplacian"),
        seed=SEED,
    )


def test_full_method_beats_baselines_on_the_small_class(class_evaluation):
    """CI's end-to-end evaluation: the README table's claims on 6 fish at 200x150.

    The same assertions as the three-class run below (marked slow), on one small class.
    """
    _assert_full_beats_baselines(summarize(class_evaluation)[CLASS])


def test_full_beats_copy_nearest_on_mean_ciede2000(class_evaluation):
    table = summarize(class_evaluation)[CLASS]
    assert table["full"]["ciede2000"] < table["copy_nearest"]["ciede2000"]


def test_full_beats_one_pass_on_structure_and_crispness(class_evaluation):
    """The paper's one pass (one scale, mean vote) is blurred: mean ΔE00 rewards that
    blur (and is a lottery of palettes on generated classes, whose palettes no shape
    predicts: 6 fish at seed 0 gave 27.4 against 26.0), so the comparison that counts is
    on structure, parts and crispness."""
    table = summarize(class_evaluation)[CLASS]
    full, one = table["full"], table["one_pass"]
    assert full["ssim"] > one["ssim"]
    assert full["part_transfer_macro"] > one["part_transfer_macro"] + 0.05
    assert full["blur_ratio"] > 2 * one["blur_ratio"]


def test_evaluation_rows_and_faulty_follow_the_class_rule(class_evaluation):
    rows = class_evaluation.rows()
    assert len(rows) == COUNT * 4
    assert [r["object"] for r in rows[:4]] == ["fish_000"] * 4
    rule = class_evaluation.rules[CLASS]
    # A labelled class: part transfer below the pastes' median, no SSIM limit (#10, b).
    assert 0 < rule.part_transfer < 1 and math.isnan(rule.ssim)
    for obj in class_evaluation.objects:
        for result in obj.results.values():
            m = result.metrics
            assert 0 <= m.part_transfer <= 1 and 0 <= m.part_transfer_macro <= 1
            assert 0 <= m.features_drawn <= m.features_measured
            assert result.faulty == (
                m.ssim < rule.ssim or m.part_transfer < rule.part_transfer or m.features_missing
            )
        # copy_nearest is a pure copy through its source map: blur ratio 1 by definition.
        assert obj.results["copy_nearest"].metrics.blur_ratio == pytest.approx(1.0)
    # Every generated fish has an eye: a small feature to measure.
    assert all(o.results["full"].metrics.features_measured >= 1 for o in class_evaluation.objects)
    # copy_nearest leaves holes where the nearest silhouette does not cover the query.
    holes = [
        (~obj.results["copy_nearest"].image.any(axis=2) & obj.mask).sum()
        for obj in class_evaluation.objects
    ]
    assert max(holes) > 0


def test_report_files_and_links(class_evaluation, tmp_path):
    paths = write_report(class_evaluation, tmp_path / "report")
    assert check_report(tmp_path / "report") == []
    with open(paths["csv"], newline="") as handle:
        reader = csv.DictReader(handle)
        assert tuple(reader.fieldnames) == CSV_COLUMNS
        rows = list(reader)
    assert {r["method"] for r in rows} == {"full", "copy_nearest", "one_pass", "laplacian"}
    assert all(r["faulty"] in ("0", "1") for r in rows)
    summary = paths["summary"].read_text()
    assert "## fish" in summary and "| full |" in summary and "Faulty when" in summary
    page = paths["html"].read_text()
    assert page.count("<section") == COUNT and "provenance" in page
    # Removing a picture is caught by the link check.
    (tmp_path / "report/images/fish_001/one_pass.png").unlink()
    assert check_report(tmp_path / "report") == ["images/fish_001/one_pass.png"]


def test_coherence_columns_in_results_and_summary(class_evaluation, tmp_path):
    from imagemap.report import COHERENCE_COLUMNS

    paths = write_report(class_evaluation, tmp_path / "report")
    with open(paths["csv"], newline="") as handle:
        rows = list(csv.DictReader(handle))
    coherence = (
        "fragments_90",
        "fragment_share",
        "seam_length",
        "continuity",
        "midtone_ratio",
        "parts_one_palette",
        "parts_palette_measured",
    )
    for column in coherence:
        assert all(row[column] != "" for row in rows), column
    summary = paths["summary"].read_text()
    for _, title, _ in COHERENCE_COLUMNS:
        assert title in summary and title in paths["html"].read_text()
    table = summarize(class_evaluation)[CLASS]
    for obj in class_evaluation.objects:
        copy = obj.results["copy_nearest"].metrics
        # A pasted example is one translation: one fragment (its holes are no fragment)
        # with seams only around its holes.
        assert copy.fragments_90 == 1 and copy.fragment_share > 0.9
        assert copy.parts_palette_measured > 0
        full = obj.results["full"].metrics
        assert full.fragments_90 > copy.fragments_90 and full.seam_length > copy.seam_length
        assert 0 < full.continuity < 1.5 and 0 < full.midtone_ratio < 5
    # Wave 3's coherence: one palette per part in 90 % of the parts at least (a paste has
    # one where the part does not fall in its holes).
    assert table["full"]["parts_one_palette"] >= 0.9
    assert table["full"]["fragments_90"] > 1  # a patch method: more than one piece


def test_method_params_of_the_baselines():
    from imagemap.depth.config import PRESETS

    fish = PRESETS["fish"]
    assert method_params("full", fish) == fish
    assert method_params("copy_nearest", fish) is None
    assert method_params("warp_nearest", fish) is None
    one = method_params("one_pass", fish)
    assert one.pyramid.patch_sizes == (7,) and one.matching.max_iterations == 0
    assert one.guides.position_weight == 0.0
    assert method_params("no_position", fish).guides.position_weight == 0.0
    assert method_params("laplacian", fish).matching.appearance_pyramid == "laplacian"
    assert fish.matching.appearance_pyramid == "gaussian"
    with pytest.raises(InputError, match="unknown method"):
        method_params("best", fish)
    assert method_params("mean_vote", fish).finish.vote == "mean" and fish.finish.vote == "copy"
    assert one.finish.vote == "mean" and not one.pyramid.grow  # Fig. 1: one level, mean vote
    paper = method_params("paper", fish)
    assert (paper.finish.vote, paper.matching.appearance_pyramid) == ("mean", "laplacian")
    assert not paper.finish.complete_features and not paper.guides.registration
    assert set(METHODS) == {
        "full",
        "copy_nearest",
        "warp_nearest",
        "one_pass",
        "mean_vote",
        "no_position",
        "laplacian",
        "paper",
    }


def test_cli_with_two_workers_matches_one(fish_dir, tmp_path, capsys):
    # Objects are shared out to the workers; one deterministic method is enough beside full.
    args = ["evaluate", str(fish_dir), "--methods", "full,copy_nearest", "--limit", "2"]
    assert main([*args, "--out", str(tmp_path / "one"), "--workers", "1"]) == 0
    assert main([*args, "--out", str(tmp_path / "two"), "--workers", "2"]) == 0
    out = capsys.readouterr().out
    assert "evaluated 2 objects x 2 methods" in out

    def metrics(path):
        with open(path / "results.csv", newline="") as handle:
            return [
                (r["object"], r["method"], r["ciede2000"], r["ssim"])
                for r in csv.DictReader(handle)
            ]

    assert metrics(tmp_path / "one") == metrics(tmp_path / "two")
    assert len(metrics(tmp_path / "one")) == 4
    assert check_report(tmp_path / "two") == []


@pytest.mark.parametrize(
    "extra, message",
    [
        (["--methods", "full,magic"], "unknown method"),
        (["--workers", "0"], "--workers"),
        (["--limit", "0"], "--limit"),
    ],
)
def test_cli_bad_input(fish_dir, tmp_path, capsys, extra, message):
    assert main(["evaluate", str(fish_dir), "--out", str(tmp_path / "r"), *extra]) == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "r").exists()


def test_cli_missing_database(tmp_path, capsys):
    assert main(["evaluate", str(tmp_path / "nowhere"), "--out", str(tmp_path / "r")]) == 2
    assert "not found" in capsys.readouterr().err


@pytest.mark.slow
@pytest.mark.parametrize("name", ["fish", "busts", "humans"])
def test_full_method_beats_baselines_on_generated_classes(name, tmp_path):
    """The README's table: 12 objects per class at the default size, seed 0 (2-3 min).

    Run with ``python -m pytest -m slow tests/test_evaluation.py``; CI runs the same
    assertions on one small class (``test_full_method_beats_baselines_on_the_small_class``).
    """
    write_class(name, tmp_path, count=12, seed=0, quiet=True)
    evaluation = leave_one_out(Database.from_directory(tmp_path), workers=2, seed=0)
    write_report(evaluation, tmp_path / "report")
    assert check_report(tmp_path / "report") == []
    _assert_full_beats_baselines(summarize(evaluation)[name])


def _assert_full_beats_baselines(table):
    full, nearest, one = table["full"], table["copy_nearest"], table["one_pass"]
    # The README's claims: the free baseline is beaten on colour, structure and detail...
    assert full["ciede2000"] < nearest["ciede2000"]
    assert full["ssim"] > nearest["ssim"]
    assert full["part_transfer_macro"] > nearest["part_transfer_macro"]
    assert full["faulty"] < nearest["faulty"]
    if not math.isnan(full["features_drawn"]):
        assert full["features_drawn"] >= nearest["features_drawn"]
    # ...and the paper's one pass on structure and crispness. (The mean vote can win
    # mean ΔE00, which rewards blur: fish 26.96 against 27.22 in the latest run.)
    assert full["ssim"] > one["ssim"]
    assert full["blur_ratio"] > 2 * one["blur_ratio"]
    # Plain colour levels put the right parts in the right places more often than the
    # paper's Laplacian bands (latest run: 0.804 / 0.790 / 0.826 against 0.744 / 0.665 /
    # 0.793).
    assert full["part_transfer_macro"] > table["laplacian"]["part_transfer_macro"]
    # Issue 10's crispness target, met since edges on seams within one example are kept
    # (latest run: 0.99 / 0.99 / 0.99).
    assert full["blur_ratio"] >= 0.9
    assert not math.isnan(full["part_accuracy"])


class _BrokenForOne(Database):
    """A database whose leave-one-out of ``fish_001`` raises (in a worker process too)."""

    def without(self, *names):
        if "fish_001" in names:
            raise InputError("fish_001: broken on purpose")
        return super().without(*names)


def _fail_for_fish_001(monkeypatch, exception):
    import imagemap.evaluation

    original = imagemap.evaluation.evaluate_object

    def flaky(database, name, **kwargs):
        if name == "fish_001":
            raise exception
        return original(database, name, **kwargs)

    monkeypatch.setattr(imagemap.evaluation, "evaluate_object", flaky)


@pytest.mark.parametrize("workers", [1, 2])
def test_a_failing_object_is_reported_and_the_others_go_on(fish_dir, tmp_path, workers):
    database = _BrokenForOne(Database.from_directory(fish_dir).examples, source=str(fish_dir))
    evaluation = leave_one_out(database, methods=("copy_nearest",), limit=3, workers=workers)
    assert [obj.name for obj in evaluation.objects] == ["fish_000", "fish_002"]
    assert evaluation.failed == [("fish_001", "fish_001: broken on purpose")]
    assert not evaluation.interrupted
    paths = write_report(evaluation, tmp_path / "report")
    assert check_report(tmp_path / "report") == []
    assert "- fish_001: failed: fish_001: broken on purpose" in paths["summary"].read_text()
    assert "fish_001: failed" in paths["html"].read_text()
    with open(paths["csv"], newline="") as handle:
        assert [r["object"] for r in csv.DictReader(handle)] == ["fish_000", "fish_002"]


def test_cli_names_a_failed_object_and_exits_1(fish_dir, tmp_path, capsys, monkeypatch):
    _fail_for_fish_001(monkeypatch, RuntimeError("boom"))
    out = tmp_path / "report"
    args = ["evaluate", str(fish_dir), "--out", str(out), "--methods", "copy_nearest"]
    assert main([*args, "--limit", "3"]) == 1
    err = capsys.readouterr().err
    assert "fish_001: failed: RuntimeError: boom" in err and "2 object(s) evaluated" in err
    assert check_report(out) == []


def test_interrupted_evaluation_keeps_what_finished(fish_dir, tmp_path, capsys, monkeypatch):
    _fail_for_fish_001(monkeypatch, KeyboardInterrupt())
    evaluation = leave_one_out(
        Database.from_directory(fish_dir), methods=("copy_nearest",), limit=3
    )
    assert evaluation.interrupted and not evaluation.failed
    assert [obj.name for obj in evaluation.objects] == ["fish_000"]
    out = tmp_path / "report"
    args = ["evaluate", str(fish_dir), "--out", str(out), "--methods", "copy_nearest"]
    assert main(args) == 130
    assert "interrupted" in capsys.readouterr().err
    assert check_report(out) == []
    assert "interrupted" in (out / "summary.md").read_text()


def test_every_object_failing_still_writes_a_report(fish_dir, tmp_path, monkeypatch):
    import imagemap.evaluation

    def broken(database, name, **kwargs):
        raise ValueError(f"{name} is broken")

    monkeypatch.setattr(imagemap.evaluation, "evaluate_object", broken)
    evaluation = leave_one_out(Database.from_directory(fish_dir), methods=("full",), limit=2)
    assert evaluation.objects == [] and len(evaluation.failed) == 2
    write_report(evaluation, tmp_path / "report")
    assert check_report(tmp_path / "report") == []


@pytest.mark.parametrize(
    "keyword, value", [("workers", 0), ("workers", 1.5), ("limit", 0), ("seed", -1)]
)
def test_leave_one_out_checks_its_arguments(fish_dir, keyword, value):
    with pytest.raises(InputError, match=keyword):
        leave_one_out(Database.from_directory(fish_dir), **{keyword: value})


def _scored_objects(faulty, ssim, features):
    """A one-class, one-method evaluation whose objects have the given values."""
    import numpy as np

    from imagemap.evaluation import Evaluation, MethodResult, ObjectEvaluation
    from imagemap.metrics import ImageMetrics

    objects = []
    for i, (bad, score, drawn) in enumerate(zip(faulty, ssim, features, strict=True)):
        metrics = ImageMetrics(
            ciede2000=20.0,
            ssim=score,
            part_accuracy=0.5,
            features_drawn=drawn or 0,
            features_measured=0 if drawn is None else 1,
        )
        result = MethodResult("full", np.zeros((2, 2, 3)), metrics, 0.0, [], faulty=bad)
        empty = np.zeros((2, 2))
        objects.append(
            ObjectEvaluation(f"fish_{i:03d}", "fish", empty, empty, empty, {"full": result})
        )
    return Evaluation(objects, {}, {}, {"fish": "fish"}, ("full",))


def test_bootstrap_intervals_known_answers():
    from imagemap.report import bootstrap_intervals

    half = _scored_objects([True, False] * 6, [0.6] * 12, [1, 0] * 6)
    row = bootstrap_intervals(half)["fish"]["full"]
    assert row["ssim"] == pytest.approx((0.6, 0.6))  # no spread, no interval
    assert row["ciede2000"] == pytest.approx((20.0, 20.0))
    # 6 of 12 faulty: the binomial spread, about +-0.28 at 95 %.
    low, high = row["faulty"]
    assert 0.15 <= low <= 0.3 and 0.7 <= high <= 0.85
    low_f, high_f = row["objects_features_drawn"]  # 6 of 12 with their feature
    assert 0.15 <= low_f <= 0.3 and 0.7 <= high_f <= 0.85
    # Unmeasured columns stay NaN; the same seed gives the same intervals.
    assert all(math.isnan(v) for v in row["blur_ratio"])
    assert bootstrap_intervals(half) == bootstrap_intervals(half)
    # More objects of the same kind: a narrower interval.
    wide = _scored_objects([True, False] * 24, [0.6] * 48, [1, 0] * 24)
    low48, high48 = bootstrap_intervals(wide)["fish"]["full"]["faulty"]
    assert high48 - low48 < 0.7 * (high - low)
    # Objects without features count for nothing in the features column.
    none = _scored_objects([False] * 4, [0.5, 0.6, 0.7, 0.8], [None] * 4)
    assert all(
        math.isnan(v) for v in bootstrap_intervals(none)["fish"]["full"]["objects_features_drawn"]
    )
    assert bootstrap_intervals(none)["fish"]["full"]["faulty"] == (0.0, 0.0)


def test_summary_intervals_hold_the_means(class_evaluation):
    from imagemap.report import INTERVAL_COLUMNS, bootstrap_intervals, summary_markdown

    table = summarize(class_evaluation)[CLASS]
    intervals = bootstrap_intervals(class_evaluation)[CLASS]
    for method, row in table.items():
        for key, _, _ in INTERVAL_COLUMNS:
            low, high = intervals[method][key]
            if not math.isnan(row[key]):
                assert low - 1e-9 <= row[key] <= high + 1e-9, (method, key)
    assert "% intervals of these means" in summary_markdown(class_evaluation)


def test_summary_names_the_code_that_ran(class_evaluation):
    # Two reports of one command and seed differed (fish 0.816 and 0.812) because one was
    # started inside another checkout, whose package ``python -m imagemap`` imported
    # before PYTHONPATH's: the summary says which package folder made it.
    import imagemap
    from imagemap.report import summary_markdown

    folder = Path(imagemap.__file__).resolve().parent
    lines = summary_markdown(class_evaluation).splitlines()
    assert f"Code: imagemap {imagemap.__version__} from `{folder}`." in lines


def test_paired_intervals_see_a_difference_the_marginal_ones_hide():
    from imagemap.evaluation import Evaluation
    from imagemap.report import bootstrap_intervals

    # SSIM spread widely over objects, and a second method 0.02 better on every one.
    scores = [0.3 + 0.05 * i for i in range(12)]
    a = _scored_objects([False] * 12, scores, [None] * 12)
    b = _scored_objects([False] * 12, [s + 0.02 for s in scores], [None] * 12)
    for obj, other in zip(a.objects, b.objects, strict=True):
        obj.results["better"] = other.results["full"]
    both = Evaluation(a.objects, {}, {}, {"fish": "fish"}, ("full", "better"))
    marginal = bootstrap_intervals(both)["fish"]
    assert marginal["better"]["ssim"][0] < marginal["full"]["ssim"][1]  # they overlap
    paired = bootstrap_intervals(both, relative_to="full")["fish"]
    assert paired["better"]["ssim"] == pytest.approx((0.02, 0.02))  # but always better
    assert paired["full"]["ssim"] == (0.0, 0.0)
