"""imagemap and EbSynth side by side: the same task, fresh processes, interleaved (#44 item 5).

The task is the outside tasks' ellipsoid fish (``ellipsoid_fish.py``: two examples and a
query, made procedurally at each size), the task ``outside.py`` already runs EbSynth on.
At each size (``--sizes``, default 200x150, 512x512, 1024x1024) the examples are written as
a database directory (``NAME_depth.npy`` float depth, ``NAME_image.png`` 8-bit map) and
the query as ``query_depth.npy``, under ``--out`` (default ``benchmarks/.data/
ebsynth_side_by_side/``). Then ``--reps`` times (default 2), interleaved (the order
flips every repetition), one after the other, never two at once:

(a) imagemap: ``python -m imagemap synthesize query_depth.npy --db db -o imagemap.png -v
    --preset fish --seed 0`` as a fresh process (this checkout's imagemap, its
    directory first on ``PYTHONPATH``). Recorded: the whole process's wall time, the
    pipeline time that ``-v`` reports (its closing ``wrote ... in X s`` line: the
    synthesis, from the example selection to the RGB map, as ``synthesize`` times it;
    reading the inputs and writing the PNG are outside it) and its stage times;
(b) EbSynth: its whole process on the same task as ``outside.py`` gives it
    (``outside.run_ebsynth``): one exemplar, the example nearest the query
    (``imagemap.select_examples``), its map as the style, and two guides, the depth and
    a position guide (bounding-box-normalised object coordinates), weights 1 and 4,
    EbSynth's other settings at their defaults (OpenMP uses every core). Its input PNGs
    are written by the driver before the clock starts; the time is EbSynth's process
    alone, reading its inputs and writing its output included;
(c) the floor: a fresh process that imports every module a 200x150 ``synthesize``
    imports and loads every numba kernel it loads from numba's cache, no work
    (``run.py``'s ``run_floor``, the cli group's floor, made by ``startup.py``). Its
    wall time includes the interpreter's start; like ``synthesize`` it skips the
    closing garbage collections (``gc.freeze()`` before exit). The table gives beside
    it, in brackets, the imports and the kernel load as timed inside the process.

Wall time and peak RSS of (a) and (b) are GNU ``/usr/bin/time``'s (``%e``, ``%M``: the
measured process alone, not this driver); the floor's are ``run_floor``'s. Before the
repetitions, one untimed warm-up of each at the first size (numba's cache, the page
cache; ``--no-warmup`` skips it).

The table gives per size the min-max over the repetitions, the ratios imagemap /
EbSynth of the minima (in brackets the range of the per-repetition ratios) and the
issue's targets: at 200x150 the pipeline <= 1.0x EbSynth's whole process and the whole
``imagemap synthesize`` process <= 1.5x; at 512x512 <= 0.4x and at 1024x1024 <= 0.35x,
taken as the whole process's ratio (the stricter reading). ``--json FILE`` writes every
figure, the machine and the 1-minute load average at the start and the end;
``imagemap.png`` and ``ebsynth.png`` of the last repetition stay in each size's folder.

Getting EbSynth
---------------
EbSynth (https://github.com/jamriska/ebsynth, public domain; it implements PatchMatch,
patented by Adobe) is not part of imagemap. Build its CPU path from source:

    git clone https://github.com/jamriska/ebsynth && cd ebsynth
    g++ src/ebsynth.cpp src/ebsynth_cpu.cpp src/ebsynth_nocuda.cpp -DNDEBUG -O3 -fopenmp \\
        -I include -std=c++11 -o bin/ebsynth

and give its binary with ``--ebsynth PATH`` or the ``EBSYNTH`` environment variable.
Without it the script says so and exits (status 2) before any work.

Usage
-----
    EBSYNTH=~/ebsynth/bin/ebsynth python benchmarks/ebsynth_side_by_side.py
    python benchmarks/ebsynth_side_by_side.py --ebsynth PATH --sizes 200x150 --reps 1
    python benchmarks/ebsynth_side_by_side.py --wait-load 2.5 --json side_by_side.json
    python benchmarks/ebsynth_side_by_side.py --compile-bytecode  # as an installed imagemap

The report says how many of imagemap's modules had current bytecode: where the environment
sets ``PYTHONDONTWRITEBYTECODE`` a checkout compiles every module from source in every
process (about 0.1 s of CPU of a 200x150 synthesis); ``--compile-bytecode`` writes it first.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shlex
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

BENCHMARKS = Path(__file__).resolve().parent
for _folder in (BENCHMARKS, BENCHMARKS.parent):  # outside.py, run.py; this checkout
    if str(_folder) not in sys.path:
        sys.path.insert(0, str(_folder))

import ellipsoid_fish  # noqa: E402
import outside  # noqa: E402
import run as bench_run  # noqa: E402

TIME = "/usr/bin/time"
TIME_FORMAT = "BENCH %e %U %S %M"
PRESET = "fish"
SEED = 0
#: The issue's targets (#44 item 5): imagemap / EbSynth, whole processes unless said.
TARGETS = {
    "200x150": {"pipeline": 1.0, "whole": 1.5},
    "512x512": {"whole": 0.4},
    "1024x1024": {"whole": 0.35},
}
EBSYNTH_HELP = (
    "EbSynth is not part of imagemap: build it from https://github.com/jamriska/ebsynth "
    "(g++ src/ebsynth.cpp src/ebsynth_cpu.cpp src/ebsynth_nocuda.cpp -DNDEBUG -O3 -fopenmp "
    "-I include -std=c++11 -o bin/ebsynth) and give its binary with --ebsynth PATH or the "
    "EBSYNTH environment variable"
)


def _timed(command: list[str], time_file: Path) -> list[str]:
    return [TIME, "-f", TIME_FORMAT, "-o", str(time_file), *command]


def _read_time(time_file: Path) -> dict:
    """GNU time's figures of one process: wall, user and system seconds, peak RSS (MB)."""
    found = re.search(r"^BENCH (\S+) (\S+) (\S+) (\d+)$", time_file.read_text(), re.M)
    if not found:
        raise RuntimeError(f"{time_file}: no figures from {TIME}: {time_file.read_text()!r}")
    wall, user, system, kb = found.groups()
    return {
        "seconds": float(wall),
        "cpu_seconds": float(user) + float(system),
        "rss_peak_mb": int(kb) / 1024.0,
    }


def make_task(folder: Path, width: int, height: int) -> dict:
    """Write the ellipsoid fish task at one size; EbSynth's exemplar (the nearest example)."""
    import imagemap
    from imagemap.io import write_image

    task = ellipsoid_fish.make_task(width, height)
    database_dir = folder / "db"
    if database_dir.exists():
        shutil.rmtree(database_dir)
    database_dir.mkdir(parents=True)
    for example in task.examples:
        np.save(database_dir / f"{example.name}_depth.npy", example.depth.astype(np.float32))
        write_image(database_dir / f"{example.name}_image.png", example.image)
    query = folder / "query_depth.npy"
    depth = task.depth.astype(np.float32)
    np.save(query, depth)
    # EbSynth's exemplar is read back from the files imagemap reads: the same bytes.
    database = imagemap.Database.from_directory(database_dir)
    nearest = database[imagemap.select_examples(depth, database, 1)[0]]
    return {"database": database_dir, "query": query, "depth": depth, "nearest": nearest}


def run_imagemap(task: dict, folder: Path) -> dict:
    """One fresh ``python -m imagemap synthesize ... -v`` process: its figures."""
    output, time_file = folder / "imagemap.png", folder / "imagemap.time"
    command = [
        sys.executable, "-m", "imagemap", "synthesize", str(task["query"]),
        "--db", str(task["database"]), "-o", str(output), "-v",
        "--preset", PRESET, "--seed", str(SEED),
    ]  # fmt: skip
    done = subprocess.run(
        _timed(command, time_file), capture_output=True, text=True, env=bench_run._child_env()
    )
    if done.returncode != 0:
        raise RuntimeError(f"imagemap synthesize failed ({done.returncode}): {done.stderr}")
    found = re.search(r"^wrote .* in ([\d.]+) s$", done.stderr, re.M)
    if not found:
        raise RuntimeError(f"imagemap synthesize -v: no 'wrote ... in X s' line: {done.stderr}")
    figures = _read_time(time_file)
    figures["pipeline_seconds"] = float(found.group(1))
    figures["stages"] = {
        name: float(seconds)
        for name, seconds in re.findall(r"^imagemap: stage (\w+): ([\d.]+) s", done.stderr, re.M)
    }
    return figures


def run_ebsynth(binary: str, task: dict, folder: Path) -> dict:
    """EbSynth's whole process on the task, through ``outside.run_ebsynth``: its figures.

    ``outside.run_ebsynth`` writes EbSynth's inputs and runs the binary it is given; it
    is given a one-line shell script that ``exec``\\ s GNU time on the real binary, so the
    figures are EbSynth's process alone.
    """
    from imagemap.io import write_image

    time_file = folder / "ebsynth.time"
    time_file.unlink(missing_ok=True)
    with tempfile.TemporaryDirectory() as scratch:
        wrapper = Path(scratch) / "ebsynth_timed.sh"
        command = " ".join(shlex.quote(part) for part in _timed([binary], time_file))
        wrapper.write_text(f'#!/bin/sh\nexec {command} "$@"\n')
        wrapper.chmod(0o755)
        image = outside.run_ebsynth(str(wrapper), task["nearest"], task["depth"])
    write_image(folder / "ebsynth.png", image)
    return _read_time(time_file)


def run_floor() -> dict:
    """``run.py``'s floor: a fresh process's imports and numba cache load, no synthesis."""
    row = bench_run.run_floor()
    keys = ("seconds", "rss_peak_mb", "import_seconds", "kernel_load_seconds")
    return {key: row[key] for key in keys}


def wait_for_load(limit: float, minutes: float) -> None:
    """Wait (checking every 60 s, up to ``minutes``) for the 1-minute load to drop below."""
    deadline = time.monotonic() + 60 * minutes
    while (load := os.getloadavg()[0]) >= limit:
        if time.monotonic() >= deadline:
            print(
                f"load {load:.2f} still >= {limit} after {minutes:g} min: running anyway",
                file=sys.stderr,
            )
            return
        print(f"load {load:.2f} >= {limit}: waiting 60 s", file=sys.stderr)
        time.sleep(60)


def _span(values: list[float], digits: int = 2) -> str:
    low, high = min(values), max(values)
    if f"{low:.{digits}f}" == f"{high:.{digits}f}":
        return f"{low:.{digits}f}"
    return f"{low:.{digits}f}–{high:.{digits}f}"


def summarise(size: str, reps: list[dict]) -> dict:
    """Minima, ranges and ratios of one size's repetitions, and the targets met."""
    ours = [r["imagemap"]["seconds"] for r in reps]
    pipeline = [r["imagemap"]["pipeline_seconds"] for r in reps]
    theirs = [r["ebsynth"]["seconds"] for r in reps]
    summary = {
        "size": size,
        "imagemap_seconds": ours,
        "pipeline_seconds": pipeline,
        "ebsynth_seconds": theirs,
        "floor_seconds": [r["floor"]["seconds"] for r in reps],
        "floor_inside_seconds": [
            r["floor"]["import_seconds"] + r["floor"]["kernel_load_seconds"] for r in reps
        ],
        "imagemap_rss_mb": max(r["imagemap"]["rss_peak_mb"] for r in reps),
        "ebsynth_rss_mb": max(r["ebsynth"]["rss_peak_mb"] for r in reps),
        "floor_rss_mb": max(r["floor"]["rss_peak_mb"] for r in reps),
        "ratio_whole": min(ours) / min(theirs),
        "ratio_pipeline": min(pipeline) / min(theirs),
        "ratio_whole_paired": [a / b for a, b in zip(ours, theirs, strict=True)],
        "ratio_pipeline_paired": [a / b for a, b in zip(pipeline, theirs, strict=True)],
        "targets": TARGETS.get(size, {}),
    }
    summary["met"] = {
        kind: summary[f"ratio_{kind}"] <= limit for kind, limit in summary["targets"].items()
    }
    return summary


def format_table(summaries: list[dict]) -> str:
    lines = [
        "| size | imagemap whole s | imagemap pipeline s | EbSynth s | ratio whole "
        "| ratio pipeline | peak RSS imagemap / EbSynth | floor s (imports + load) | target |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---|",
    ]
    for s in summaries:
        target = (
            ", ".join(
                f"{kind} ≤ {limit:g}× ({'met' if s['met'][kind] else 'not met'})"
                for kind, limit in s["targets"].items()
            )
            or "–"
        )
        lines.append(
            f"| {s['size']} | {_span(s['imagemap_seconds'])} | {_span(s['pipeline_seconds'])} "
            f"| {_span(s['ebsynth_seconds'])} "
            f"| {s['ratio_whole']:.2f} ({_span(s['ratio_whole_paired'])}) "
            f"| {s['ratio_pipeline']:.2f} ({_span(s['ratio_pipeline_paired'])}) "
            f"| {s['imagemap_rss_mb']:.0f} / {s['ebsynth_rss_mb']:.0f} MB "
            f"| {_span(s['floor_seconds'])} ({_span(s['floor_inside_seconds'])}) | {target} |"
        )
    return "\n".join(lines)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        description=(__doc__ or "").split("\n\n")[0],
        epilog=__doc__.split("\n", 2)[2],
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "--ebsynth",
        default=os.environ.get("EBSYNTH"),
        help="EbSynth's binary (default: the EBSYNTH environment variable)",
    )
    parser.add_argument(
        "--sizes",
        default="200x150,512x512,1024x1024",
        help="WIDTHxHEIGHT,... (default: %(default)s)",
    )
    parser.add_argument("--reps", type=int, default=2, help="repetitions per size (default 2)")
    parser.add_argument(
        "--out",
        type=Path,
        default=BENCHMARKS / ".data" / "ebsynth_side_by_side",
        help="task files and the maps, one folder per size (default: %(default)s)",
    )
    parser.add_argument("--json", type=Path, help="write every figure here")
    parser.add_argument(
        "--wait-load",
        type=float,
        default=0.0,
        metavar="LOAD",
        help="before starting, wait until the 1-minute load average is below LOAD "
        "(checked every 60 s; default: do not wait)",
    )
    parser.add_argument(
        "--wait-minutes",
        type=float,
        default=30.0,
        help="give up waiting for --wait-load after this long and run anyway (default 30)",
    )
    parser.add_argument("--no-warmup", action="store_true", help="skip the untimed warm-up")
    parser.add_argument(
        "--compile-bytecode",
        action="store_true",
        help="write this checkout's bytecode first (python -m compileall), as an installed "
        "imagemap has it: with PYTHONDONTWRITEBYTECODE set, a checkout's modules are "
        "compiled from source in every process (startup.py's option of the same name)",
    )
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    binary = args.ebsynth
    if not binary:
        print(f"ebsynth_side_by_side: no EbSynth binary given. {EBSYNTH_HELP}.", file=sys.stderr)
        return 2
    if not (Path(binary).is_file() and os.access(binary, os.X_OK)):
        print(
            f"ebsynth_side_by_side: {binary}: no such executable. {EBSYNTH_HELP}.", file=sys.stderr
        )
        return 2
    if not os.access(TIME, os.X_OK):
        print(
            f"ebsynth_side_by_side: {TIME} (GNU time) not found: it measures each process",
            file=sys.stderr,
        )
        return 2
    if args.reps < 1:
        print("ebsynth_side_by_side: --reps must be at least 1", file=sys.stderr)
        return 2
    binary = str(Path(binary).resolve())
    sizes = outside._parse_sizes(args.sizes)
    if args.compile_bytecode:
        subprocess.run(
            [sys.executable, "-m", "compileall", "-q", str(BENCHMARKS.parent / "imagemap")],
            check=True, stdout=subprocess.DEVNULL,
        )  # fmt: skip
    import startup  # deferred: the driver's start-up (its bytecode count only)

    current, total = startup.bytecode_state(BENCHMARKS.parent)
    print(f"imagemap modules with current bytecode: {current} of {total}")
    if args.wait_load > 0:
        wait_for_load(args.wait_load, args.wait_minutes)
    load_start = os.getloadavg()
    print(f"load average at start: {load_start[0]:.2f} {load_start[1]:.2f} {load_start[2]:.2f}")
    report = {
        "task": "ellipsoid fish (benchmarks/ellipsoid_fish.py): two examples and a query; "
        "EbSynth: the nearest example, depth and position guides (outside.run_ebsynth)",
        "ebsynth": binary,
        "imagemap_command": f"python -m imagemap synthesize QUERY --db DB -o OUT -v "
        f"--preset {PRESET} --seed {SEED}",
        "reps": args.reps,
        "machine": bench_run.machine(),
        "load_start": list(load_start),
        "bytecode": f"{current} of {total}",
        "sizes": [],
    }
    summaries = []
    for index, (width, height) in enumerate(sizes):
        size = f"{width}x{height}"
        folder = args.out / size
        folder.mkdir(parents=True, exist_ok=True)
        task = make_task(folder, width, height)
        if index == 0 and not args.no_warmup:
            warm = {
                "imagemap": run_imagemap(task, folder),
                "ebsynth": run_ebsynth(binary, task, folder),
            }
            report["warmup"] = {"size": size, **warm}
            print(
                f"warm-up {size}: imagemap {warm['imagemap']['seconds']:.2f} s, "
                f"EbSynth {warm['ebsynth']['seconds']:.2f} s",
                file=sys.stderr,
            )
        reps = []
        for rep in range(args.reps):
            order = ["imagemap", "ebsynth", "floor"]
            if rep % 2:
                order.reverse()
            figures = {"order": order, "load": os.getloadavg()[0]}
            for kind in order:
                if kind == "imagemap":
                    figures[kind] = run_imagemap(task, folder)
                elif kind == "ebsynth":
                    figures[kind] = run_ebsynth(binary, task, folder)
                else:
                    figures[kind] = run_floor()
            reps.append(figures)
            print(
                f"{size} rep {rep + 1}: imagemap {figures['imagemap']['seconds']:.2f} s "
                f"(pipeline {figures['imagemap']['pipeline_seconds']:.2f} s), EbSynth "
                f"{figures['ebsynth']['seconds']:.2f} s, "
                f"floor {figures['floor']['seconds']:.2f} s, "
                f"load {figures['load']:.2f}",
                file=sys.stderr,
            )
        summary = summarise(size, reps)
        summaries.append(summary)
        report["sizes"].append({**summary, "reps": reps, "nearest": task["nearest"].name})
    load_end = os.getloadavg()
    report["load_end"] = list(load_end)
    print()
    print(format_table(summaries))
    print(f"\nload average at end: {load_end[0]:.2f} {load_end[1]:.2f} {load_end[2]:.2f}")
    print(f"maps: {args.out}/SIZE/imagemap.png, ebsynth.png (the last repetition's)")
    if args.json:
        args.json.write_text(json.dumps(report, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
