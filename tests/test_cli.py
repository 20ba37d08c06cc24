"""The command line end to end, and its answers to bad input."""

import json

import numpy as np
import pytest

from imagemap.cli import main
from imagemap.io import read_image, write_image


def write_db(root, database):
    root.mkdir(parents=True, exist_ok=True)
    for example in database:
        depth16 = np.round(example.depth * 65535).astype(np.uint16)
        write_image(root / f"{example.name}_depth.png", depth16)
        write_image(root / f"{example.name}_image.png", example.image)
    return root


@pytest.fixture
def files(tmp_path, blob_database, query_blob):
    db = write_db(tmp_path / "db", blob_database)
    depth, _ = query_blob
    query = tmp_path / "query_depth.png"
    write_image(query, np.round(depth * 65535).astype(np.uint16))
    return db, query, depth


def test_synthesize_end_to_end(files, tmp_path):
    db, query, depth = files
    out = tmp_path / "out" / "map.png"
    prov = tmp_path / "prov.png"
    report = tmp_path / "report.json"
    preview = tmp_path / "preview.png"
    code = main(
        [
            "synthesize",
            "--preview",
            str(preview),
            str(query),
            "--db",
            str(db),
            "-o",
            str(out),
            "--provenance",
            str(prov),
            "--report",
            str(report),
            "--quiet",
            "--m",
            "2",
        ]
    )
    assert code == 0
    import imageio.v3 as iio

    rgba = iio.imread(out)
    assert rgba.shape == (*depth.shape, 4)
    # Transparent exactly where the depth is background.
    np.testing.assert_array_equal(rgba[..., 3] > 0, depth > 0)
    assert read_image(prov).shape == (*depth.shape, 3)
    # Preview: 2 x 2 panels of the depth's size.
    assert read_image(preview).shape[0] > 2 * depth.shape[0]
    info = json.loads(report.read_text())
    assert len(info["examples"]) == 2 and info["seconds"] > 0


def test_synthesize_background_colour_and_examples(files, tmp_path):
    db, query, depth = files
    out = tmp_path / "map.png"
    code = main(
        [
            "synthesize",
            str(query),
            "--db",
            str(db),
            "-o",
            str(out),
            "--quiet",
            "--background",
            "white",
            "--examples",
            "blob_2",
        ]
    )
    assert code == 0
    image = read_image(out)
    assert np.all(image[depth == 0] == 1.0)


def _run_one(command, files, tmp_path, argv):
    """``imagemap synthesize`` of the query, or ``imagemap batch`` of a folder holding
    only it (one worker: in this process), with the busts preset and ``argv``."""
    db, query, _ = files
    if command == "synthesize":
        target = [str(query), "--db", str(db), "-o", str(tmp_path / "m.png")]
    else:
        inputs = tmp_path / "inputs"
        inputs.mkdir()
        (inputs / query.name).write_bytes(query.read_bytes())
        target = [str(inputs), "--db", str(db), "-o", str(tmp_path / "out"), "--workers", "1"]
    return main([command, *target, "--preset", "busts", "-q", *argv])


@pytest.mark.parametrize("command", ["synthesize", "batch"])
@pytest.mark.parametrize("argv, expected", [([], 0.3), (["--edge-support", "0"], 0.0)])
def test_edge_support_reaches_the_blend(files, tmp_path, monkeypatch, command, argv, expected):
    import imagemap.depth.finish

    seen = []
    original = imagemap.depth.finish.seamless_copy

    def recording(*args, **kwargs):
        seen.append(kwargs["edge_support"])
        return original(*args, **kwargs)

    monkeypatch.setattr(imagemap.depth.finish, "seamless_copy", recording)
    assert _run_one(command, files, tmp_path, argv) == 0
    assert seen == [expected]


def _count_calls(monkeypatch, module, name):
    """Replace ``module.name`` with a wrapper that records each call; return the record."""
    calls = []
    original = getattr(module, name)

    def recording(*args, **kwargs):
        calls.append(1)
        return original(*args, **kwargs)

    monkeypatch.setattr(module, name, recording)
    return calls


@pytest.mark.parametrize("command", ["synthesize", "batch"])
@pytest.mark.parametrize("argv, expected", [([], 1), (["--no-feature-completion"], 0)])
def test_feature_completion_can_be_switched_off(
    files, tmp_path, monkeypatch, command, argv, expected
):
    import imagemap.depth.completion

    calls = _count_calls(monkeypatch, imagemap.depth.completion, "complete_features")
    assert _run_one(command, files, tmp_path, argv) == 0
    assert len(calls) == expected


def bad_cases(tmp_path, db, query):
    empty = tmp_path / "empty_depth.png"
    write_image(empty, np.zeros((40, 40), np.uint16))
    broken = tmp_path / "broken_db"
    broken.mkdir()
    write_image(broken / "a_depth.png", np.full((40, 40), 30000, np.uint16))
    write_image(broken / "a_image.png", np.zeros((30, 40, 3)))
    unpaired = tmp_path / "unpaired_db"
    unpaired.mkdir()
    write_image(unpaired / "b_depth.png", np.full((40, 40), 30000, np.uint16))
    return {
        "missing query": ([str(tmp_path / "nope.png"), "--db", str(db)], "file not found"),
        "no foreground": ([str(empty), "--db", str(db)], "no foreground"),
        "mismatched pair": ([str(query), "--db", str(broken)], "a_image.png"),
        "unpaired": ([str(query), "--db", str(unpaired)], "no image-map"),
        "missing db": ([str(query), "--db", str(tmp_path / "nodb")], "not found"),
        "unknown example": ([str(query), "--db", str(db), "--examples", "zzz"], "zzz"),
    }


@pytest.mark.parametrize(
    "case",
    [
        "missing query",
        "no foreground",
        "mismatched pair",
        "unpaired",
        "missing db",
        "unknown example",
    ],
)
def test_bad_input_fails_cleanly(files, tmp_path, capsys, case):
    db, query, _ = files
    argv, message = bad_cases(tmp_path, db, query)[case]
    out = tmp_path / "result.png"
    code = main(["synthesize", *argv, "-o", str(out), "--quiet"])
    assert code != 0
    assert message in capsys.readouterr().err
    assert not out.exists()
    assert not list(tmp_path.glob(".result*"))  # no temporary left behind


def test_db_check(files, tmp_path, capsys):
    db, _, _ = files
    assert main(["db", "check", str(db)]) == 0
    assert "5 readable example(s)" in capsys.readouterr().out
    (db / "lonely_depth.png").write_bytes((db / "blob_0_depth.png").read_bytes())
    assert main(["db", "check", str(db)]) == 1
    assert "lonely" in capsys.readouterr().out


def test_help_teaches(capsys):
    with pytest.raises(SystemExit):
        main(["synthesize", "--help"])
    text = capsys.readouterr().out
    assert "examples:" in text and "--preset" in text


def test_batch_writes_a_database_of_results(files, tmp_path, blob_database):
    db, query, depth = files
    second = tmp_path / "other_depth.png"
    write_image(second, np.round(blob_database[1].depth * 65535).astype(np.uint16))
    out = tmp_path / "maps"
    report = tmp_path / "batch.json"
    argv = ["synthesize", str(query), str(second), "--db", str(db), "-o", str(out)]
    assert main([*argv, "--provenance", str(tmp_path / "prov"), "--report", str(report), "-q"]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["other_image.png", "query_image.png"]
    assert len(list((tmp_path / "prov").iterdir())) == 2
    assert [r["query"] for r in json.loads(report.read_text())] == [str(query), str(second)]


def test_batch_checks_every_input_before_any_work(files, tmp_path, capsys):
    db, query, _ = files
    out = tmp_path / "maps"
    missing = tmp_path / "missing_depth.png"
    assert main(["synthesize", str(query), str(missing), "--db", str(db), "-o", str(out)]) == 2
    assert "missing_depth.png" in capsys.readouterr().err
    assert not out.exists()
