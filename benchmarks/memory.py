"""Peak memory and time of a colorization, stage by stage, in a fresh process per size.

For each size (generated fish, 2 examples and a held-out query, the data of
``benchmarks/run.py``'s square sizes) a fresh Python process runs one
``colorize(depth, database, preset="fish", m=2, seed=0)`` as ``imagemap synthesize``
would for one depth map (large blocks in their own mappings,
:func:`imagemap.cli._map_large_blocks`; the kernels loaded by
:func:`imagemap.cli.lean_kernel_loads`; the database opened with ``keep_arrays=False``;
``--library`` runs it as a library call does: glibc's default, numba's own load, the
arrays kept) and reports, per stage of the pipeline
(:data:`imagemap.depth.pipeline.STAGES`) and per phase of the engine:

- the wall time (``time.perf_counter`` around the stage);
- the peak resident set reached *during* the stage: the kernel's high-water mark
  ``VmHWM`` of ``/proc/self/status``, reset to the current resident set just before
  the stage by writing "5" to ``/proc/self/clear_refs`` (Linux >= 4.0). The mark is
  exact (the kernel updates it on every page fault that grows the resident set),
  where a sampling thread would miss peaks shorter than its interval and needs the GIL,
  which the numba kernels release but NumPy's long calls may not. The engine's phases
  (``synthesize.features``, ``.search`` ...) are read the same way at each of the
  engine's ``Timer.add`` marks, so each phase's peak also covers the untimed code
  since the previous mark.

The process's whole peak is the largest mark of its life (imports, loading, every
stage): ``getrusage``'s ``ru_maxrss`` cannot be used, as the kernel's reset clears it
too. Beside the measured figures it prints the memory guard's estimate
(:func:`imagemap.depth.budget.colorize_estimate`: bytes the run adds to the process,
and seconds) against the measured peak minus the resident set before the call (what
the estimate models) and the wall time of the call, and their ratios.

Usage
-----
    python benchmarks/memory.py --sizes 1024,2048           # a table per size
    python benchmarks/memory.py --sizes 512 --save-maps DIR  # also the maps (PNG, hashed)
    python benchmarks/memory.py --json out.json
    python benchmarks/memory.py --task benchmarks/.data/ebsynth_side_by_side/1024x1024

4096² takes about ten minutes and 3-5 GB on 2 cores.
"""

from __future__ import annotations

import argparse
import gc
import hashlib
import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path

BENCHMARKS = Path(__file__).resolve().parent
if str(BENCHMARKS.parent) not in sys.path:
    # Run as a script from a checkout: import this checkout's imagemap and data_gen.
    sys.path.insert(0, str(BENCHMARKS.parent))

MB = 2**20


def _status_mb(key: str) -> float:
    text = Path("/proc/self/status").read_text()
    found = re.search(rf"^{key}:\s+(\d+) kB", text, re.MULTILINE)
    return int(found.group(1)) / 1024.0 if found else float("nan")


class PeakMarks:
    """Peaks of ``VmHWM`` between marks: :meth:`mark` returns the peak since the last
    mark (or reset) and resets the kernel's high-water mark to the current resident set."""

    def __init__(self) -> None:
        self.lifetime_mb = _status_mb("VmHWM")  # imports and loading, before any reset
        self.since_start_mb = 0.0  # the largest mark since :meth:`start`
        self.taken_mb: list[float] = []  # every mark, in order

    def reset(self) -> None:
        with open("/proc/self/clear_refs", "w") as handle:
            handle.write("5")

    def start(self) -> None:
        """Begin a span made of several marks (a stage with the engine's phases inside);
        the peak until now is kept as a mark of its own."""
        self.mark()
        self.since_start_mb = 0.0

    def mark(self) -> float:
        peak = _status_mb("VmHWM")
        self.lifetime_mb = max(self.lifetime_mb, peak)
        self.since_start_mb = max(self.since_start_mb, peak)
        self.taken_mb.append(peak)
        self.reset()
        return peak


def _kernel_caches() -> list[Path]:
    """numba's cache index files of imagemap's kernels (``__pycache__`` beside the
    sources, or ``NUMBA_CACHE_DIR``)."""
    import imagemap

    places = [Path(imagemap.__file__).parent]
    if os.environ.get("NUMBA_CACHE_DIR"):
        places.append(Path(os.environ["NUMBA_CACHE_DIR"]))
    return [index for place in places for index in place.rglob("*.nbi")]


def _child(class_dir: str, save: str | None, library: bool) -> dict:
    """One colorization in this (fresh) process, measured stage by stage.

    ``class_dir``: a generated class (its examples, the query in ``holdout/``), or a task
    folder of ``ebsynth_side_by_side.py`` (``db/`` and ``query_depth.npy``)."""
    started = time.perf_counter()
    import numpy as np

    import imagemap.depth.pipeline as pipeline
    from imagemap import Database, colorize, read_depth
    from imagemap.core import solver
    from imagemap.core.stages import Stage
    from imagemap.depth.budget import colorize_estimate
    from imagemap.depth.config import resolve_config

    if not library:
        from imagemap.cli import _map_large_blocks, lean_kernel_loads

        _map_large_blocks()  # as `imagemap synthesize` does for maps of a megapixel or more
        lean_kernel_loads()  # as `imagemap synthesize` loads its kernels
    imports_mb = _status_mb("VmRSS")
    imports_seconds = time.perf_counter() - started
    marks = PeakMarks()
    marks.reset()

    stages: list[dict] = []
    phases: dict[str, dict] = {}

    def measured(stage):
        def run(state, config):
            before = _status_mb("VmRSS")
            marks.start()
            start = time.perf_counter()
            state = stage.run(state, config)
            seconds = time.perf_counter() - start
            marks.mark()
            peak = marks.since_start_mb  # the engine's phase marks reset the mark inside
            after = _status_mb("VmRSS")
            stages.append(
                {"stage": stage.name, "seconds": seconds, "rss_before_mb": before,
                 "rss_peak_mb": peak, "rss_after_mb": after}
            )  # fmt: skip
            return state

        return Stage(stage.name, run, stage.wanted)

    original_add = solver.Timer.add

    def add(timer, phase, start):
        original_add(timer, phase, start)
        peak = marks.mark()
        entry = phases.setdefault(phase, {"seconds": 0.0, "rss_peak_mb": 0.0})
        entry["seconds"] = timer.seconds[phase]
        entry["rss_peak_mb"] = max(entry["rss_peak_mb"], peak)

    pipeline.STAGES = tuple(measured(stage) for stage in pipeline.STAGES)
    solver.Timer.add = add  # type: ignore[method-assign]

    # One query, as `imagemap synthesize` opens the database for one depth map: the
    # examples' arrays are dropped once the synthesis has posed them.
    task = Path(class_dir, "query_depth.npy").is_file()
    database = Database.from_directory(
        Path(class_dir, "db") if task else class_dir, keep_arrays=library
    )
    if task:
        depth = read_depth(Path(class_dir, "query_depth.npy"))
    else:
        depth = read_depth(sorted(Path(class_dir, "holdout").glob("*_depth.png"))[0])
    estimate = colorize_estimate(depth, database, resolve_config("fish", m=2))
    gc.collect()
    rss_before_mb = _status_mb("VmRSS")
    marks.start()
    first_mark = len(marks.taken_mb)
    # Kernels compiled during the call (a fresh checkout, an edited kernel file): the
    # JIT's memory stays resident (4096^2: about 100 MB more at the blend's peak, the
    # same code 1711 MB compiling and 1610 MB from the cache), so such a run is marked.
    call_started = time.time()
    cpu_start = os.times()
    start = time.perf_counter()
    result = colorize(depth, database, preset="fish", m=2, seed=0)
    seconds = time.perf_counter() - start
    cpu_end = os.times()
    # CPU time beside the wall time: on a shared machine the wall time is the load's too.
    cpu_seconds = (cpu_end.user - cpu_start.user) + (cpu_end.system - cpu_start.system)
    marks.mark()
    call_peak_mb = max(marks.taken_mb[first_mark:])
    compiled = sum(index.stat().st_mtime >= call_started for index in _kernel_caches())

    # Imported after the call: the measure's own modules (SciPy's sparse graphs, 11 MB
    # resident) are no part of what a synthesis holds (`imagemap synthesize` imports none).
    from imagemap.metrics.coherence import fragments

    image = np.ascontiguousarray(result.image)
    digest = hashlib.sha256(image.tobytes()).hexdigest()
    split = fragments(result.source, result.mask)
    if save:
        from imagemap.io import write_image

        write_image(save, result.rgba)
        # The source map beside it (example, y, x per pixel: the fragments can be drawn).
        np.save(Path(save).with_suffix(".source.npy"), result.source)
    return {
        "class_dir": class_dir,
        "shape": list(depth.shape),
        "object_pixels": int(result.mask.sum()),
        "imports_seconds": imports_seconds,
        "imports_rss_mb": imports_mb,
        "rss_before_call_mb": rss_before_mb,
        "seconds": seconds,
        "cpu_seconds": cpu_seconds,
        "call_peak_mb": call_peak_mb,
        "process_peak_mb": marks.lifetime_mb,
        "stages": stages,
        "engine_phases": phases,
        "estimate_mb": estimate.bytes / MB,
        "estimate_seconds": estimate.seconds,
        "image_sha256": digest,
        "fragments_90": split.count_90,
        "fragments": split.count,
        "load_average": list(os.getloadavg()),
        "mmap_large_blocks": not library,
        "kernels_compiled": compiled,
    }


def run_size(
    side: int, data_dir: Path, save_dir: Path | None, library: bool, task: Path | None = None
) -> dict:
    from run import _child_env, fish_class  # benchmarks/run.py: the same generated fish

    class_dir = task if task is not None else fish_class(data_dir, (side, side))
    command = [sys.executable, __file__, "--child", str(class_dir)]
    if save_dir:
        save_dir.mkdir(parents=True, exist_ok=True)
        command += ["--save", str(save_dir / f"fish_{side}.png")]
    if library:
        command.append("--library")
    load_before = os.getloadavg()[0]
    done = subprocess.run(command, capture_output=True, text=True, env=_child_env())
    if done.returncode != 0:
        raise RuntimeError(f"{side}x{side} failed: {done.stderr.strip()[-2000:]}")
    figures = json.loads(done.stdout.strip().splitlines()[-1])
    figures["side"] = figures["shape"][0] if task is not None else side
    figures["load_before"] = load_before
    return figures


def format_figures(figures: dict) -> str:
    """A markdown table of one run: stages and engine phases, then the totals."""
    side = figures["side"]
    base = figures["rss_before_call_mb"]
    lines = [
        f"### {side}x{side} (object {figures['object_pixels']} px; load "
        f"{figures['load_before']:.2f} before, {figures['load_average'][0]:.2f} after)",
        "",
        "| stage | s | peak RSS MB | peak − RSS before call MB | RSS after MB |",
        "|---|---:|---:|---:|---:|",
    ]
    for stage in figures["stages"]:
        lines.append(
            f"| {stage['stage']} | {stage['seconds']:.2f} | {stage['rss_peak_mb']:.0f} | "
            f"{stage['rss_peak_mb'] - base:.0f} | {stage['rss_after_mb']:.0f} |"
        )
        if stage["stage"] == "synthesize":
            for phase, entry in figures["engine_phases"].items():
                lines.append(
                    f"| · synthesize.{phase} | {entry['seconds']:.2f} | "
                    f"{entry['rss_peak_mb']:.0f} | {entry['rss_peak_mb'] - base:.0f} | |"
                )
    added = figures["call_peak_mb"] - base
    lines += [
        "",
        f"imports {figures['imports_seconds']:.2f} s / {figures['imports_rss_mb']:.0f} MB; "
        f"RSS before the call {base:.0f} MB; call {figures['seconds']:.1f} s "
        f"({figures['cpu_seconds']:.1f} s CPU), peak "
        f"{figures['call_peak_mb']:.0f} MB (added {added:.0f} MB); whole process peak "
        f"{figures['process_peak_mb']:.0f} MB",
        f"guard estimate: {figures['estimate_mb']:.0f} MB added (measured {added:.0f}, "
        f"estimate/measured {figures['estimate_mb'] / added:.2f}); "
        f"{figures['estimate_seconds']:.1f} s (measured {figures['seconds']:.1f}, "
        f"{figures['estimate_seconds'] / figures['seconds']:.2f})",
        f"fragments for 90 %: {figures['fragments_90']} (of {figures['fragments']}); "
        f"map sha256 {figures['image_sha256'][:16]}",
    ]
    if figures.get("kernels_compiled"):
        lines.append(
            f"WARNING: numba compiled {figures['kernels_compiled']} kernels during the call "
            "(no valid cache): the peaks include the JIT's memory; run again to measure"
        )
    return "\n".join([*lines, ""])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", default="1024,2048", help="square sides, comma-separated")
    parser.add_argument(
        "--data", type=Path, default=BENCHMARKS / ".data", help="generated data (cached)"
    )
    parser.add_argument("--save-maps", type=Path, help="write each map as a PNG here")
    parser.add_argument("--json", type=Path, help="write the figures as JSON")
    parser.add_argument(
        "--library",
        action="store_true",
        help="as a library call: glibc's default allocator (no mallopt), numba's own "
        "kernel load, the database's arrays kept",
    )
    parser.add_argument(
        "--task",
        type=Path,
        help="instead of --sizes: a task folder of ebsynth_side_by_side.py (db/ and "
        "query_depth.npy, e.g. benchmarks/.data/ebsynth_side_by_side/1024x1024)",
    )
    parser.add_argument("--child", help=argparse.SUPPRESS)
    parser.add_argument("--save", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        print(json.dumps(_child(args.child, args.save, args.library)))
        return 0
    results = []
    sides = [0] if args.task else [int(s) for s in args.sizes.split(",")]
    for side in sides:
        figures = run_size(side, args.data, args.save_maps, args.library, args.task)
        results.append(figures)
        print(format_figures(figures), flush=True)
        if args.json:
            args.json.write_text(json.dumps(results, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
