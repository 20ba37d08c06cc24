"""Start-up: fresh ``imagemap`` processes against the interpreter's own floor (#44 item 1).

Each case is a fresh process, timed from this driver (wall time around the child, and
the child's own CPU time, user + system, from ``os.wait4``), ``--reps`` times,
interleaved (every repetition runs every case of every checkout once, the order
reversed each repetition), one process at a time; the table gives the median of each:

- ``python -S -c pass`` and ``python -c pass``: the interpreter alone, without and with
  ``site`` (the installed packages' ``.pth`` files run at every start);
- ``imagemap --help`` and ``imagemap synthesize --help`` (``python -m imagemap``);
- the floor: a process that imports every module a synthesis imports and loads every
  numba kernel it calls from numba's cache, and does no work (:data:`FLOOR_CHILD`);
- ``imagemap synthesize`` of the held-out fish of a generated class at ``--size``
  (default 200x150, two examples, ``--preset fish --m 2 -q``), the whole process.

The floor follows the code it measures: before the timed runs (after one untimed
synthesis per checkout that fills numba's cache) one more untimed synthesis per
checkout (:data:`RECORD_CHILD`, the same command run by ``imagemap.cli.main`` with
``-X importtime``) records the modules loaded at its end and each numba kernel it loaded
(module, name and signature); the floor imports those modules (in sorted order) and
loads those kernels (``dispatcher.compile(signature)``, which reads numba's cache as the
first call does). Modules that numba imports while it loads the first kernel (its
typing and lowering registries) are left to the kernel load, as in the synthesis. Like
``imagemap``, the floor collects garbage every 10,000 allocations and freezes the heap
before exit (:func:`imagemap.cli.main`).

The recording run also gives a breakdown of one synthesis process: the interpreter's
start (to the child's first line), the imports (``-X importtime``: the top-level imports'
cumulative times, those made while numba loaded a kernel excepted), numba's kernel loads
(the time and the number of kernels: each ``Dispatcher.compile`` the synthesis called),
the pipeline's own work (the ``wrote ... in X s`` of ``-v``, less the kernel loads and
the imports made in it) and the rest (the parser, reading the database, writing the
PNGs, the exit). ``-X importtime`` makes that process a little
slower than the timed ones.

``--before DIR`` runs every case on a second checkout too (its own directory first on
``PYTHONPATH``, as ``cd DIR && PYTHONPATH=DIR python -m imagemap``), interleaved with
this one, and gives the ratios after / before (of wall and of CPU time: the median of
the repetitions' own ratios, each repetition's two processes run back to back, and
their range) and whether the two syntheses wrote byte-identical PNGs (SHA-256 of every
file written).

Python compiles a module without cached bytecode (``__pycache__/*.pyc``) from its source
in every process that imports it: an installed imagemap has it (``pip`` writes it), a
checkout gets it on its first run unless ``PYTHONDONTWRITEBYTECODE`` is set. The table
says how many of each checkout's modules have current bytecode; ``--compile-bytecode``
writes it first (``python -m compileall``; ``__pycache__`` is ignored by git).

Usage
-----
    python benchmarks/startup.py                            # 5 repetitions
    python benchmarks/startup.py --reps 9 --before /tmp/main --json startup.json
    python benchmarks/startup.py --compile-bytecode --size 256x192
"""

from __future__ import annotations

import argparse
import hashlib
import importlib.util
import json
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

BENCHMARKS = Path(__file__).resolve().parent
ROOT = BENCHMARKS.parent
if str(BENCHMARKS) not in sys.path:
    sys.path.insert(0, str(BENCHMARKS))

#: Run by the recording synthesis (``python -X importtime -c RECORD_CHILD PLAN ARGS``):
#: ``imagemap.cli.main`` as the ``imagemap`` program runs it, each numba kernel load timed
#: (the outermost ``Dispatcher.compile`` of each call) and the plan of the floor written.
RECORD_CHILD = r"""
import time
START = time.time()
import base64, json, pickle, sys
import numba.core.dispatcher as _dispatcher

loads, depth = [], [0]
_compile = _dispatcher.Dispatcher.compile

def compile(self, sig):
    if depth[0]:
        return _compile(self, sig)
    depth[0] += 1
    before, begin = set(sys.modules), time.perf_counter()
    try:
        return _compile(self, sig)
    finally:
        depth[0] -= 1
        loads.append({
            "module": self.py_func.__module__, "name": self.py_func.__qualname__,
            "signature": base64.b64encode(pickle.dumps(sig)).decode(),
            "seconds": time.perf_counter() - begin,
            "new_modules": sorted(set(sys.modules) - before),
        })

_dispatcher.Dispatcher.compile = compile
plan_path = sys.argv[1]
sys.argv = ["imagemap", *sys.argv[2:]]
from imagemap.cli import main
try:
    code = main()
finally:
    during = {name for load in loads for name in load["new_modules"]}
    plan = {
        "start": START,
        "modules": sorted(name for name in sys.modules if name not in during),
        "kernels": loads,
    }
    with open(plan_path, "w") as handle:
        json.dump(plan, handle)
sys.exit(code)
"""

#: The floor (``python -c FLOOR_CHILD PLAN``): import the plan's modules, load its
#: kernels from numba's cache, no work; prints the two phases' seconds.
FLOOR_CHILD = r"""
import gc, time
begin = time.perf_counter()
try:  # as imagemap.cli.main
    from imagemap.cli import GC_THRESHOLDS
except ImportError:  # a checkout from before the constant
    GC_THRESHOLDS = (10_000, 10, 10)
gc.set_threshold(*GC_THRESHOLDS)
import base64, contextlib, importlib, json, pickle, sys, warnings

try:  # as `imagemap synthesize`: optional imports skipped, kernels linked lean
    from imagemap.cli import lean_kernel_loads, skip_optional_imports
except ImportError:  # a checkout from before them
    lean_kernel_loads, skip_optional_imports = None, None
try:  # ... and the rest of its start (SciPy's docstrings left as they are)
    from imagemap.cli import lean_start
except ImportError:  # a checkout from before it
    lean_start = None
plan = json.load(open(sys.argv[1]))
with warnings.catch_warnings(), (
    lean_start(True) if lean_start
    else skip_optional_imports(True) if skip_optional_imports
    else contextlib.nullcontext()
):
    warnings.simplefilter("ignore")  # deprecated aliases (numpy.core...) imported by name
    for name in plan["modules"]:
        if name != "__main__":
            try:
                importlib.import_module(name)
            except Exception:  # a module made at run time, not importable by name
                pass
imported = time.perf_counter()
if lean_kernel_loads:
    lean_kernel_loads()
for kernel in plan["kernels"]:
    function = importlib.import_module(kernel["module"])
    for part in kernel["name"].split("."):
        function = getattr(function, part)
    function.compile(pickle.loads(base64.b64decode(kernel["signature"])))
loaded = time.perf_counter()
status = open("/proc/self/status").read() if sys.platform.startswith("linux") else ""
hwm = [line.split()[1] for line in status.splitlines() if line.startswith("VmHWM:")]
print(json.dumps({"imports": imported - begin, "kernel_load": loaded - imported,
                  "rss_peak_mb": int(hwm[0]) / 1024 if hwm else float("nan")}))
gc.freeze()  # as imagemap.cli.main: no closing collections
"""


def _env(checkout: Path) -> dict:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(checkout)
    return env


def timed(command: list[str], checkout: Path) -> dict:
    """Run ``command`` in ``checkout`` (its own directory first on the path): wall seconds
    (this driver's clock around the child), the child's CPU seconds, and its output."""
    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        begin = time.perf_counter()
        child = subprocess.Popen(command, cwd=checkout, env=_env(checkout), stdout=out, stderr=err)
        _, status, usage = os.wait4(child.pid, 0)
        wall = time.perf_counter() - begin
        child.returncode = os.waitstatus_to_exitcode(status)
        out.seek(0)
        err.seek(0)
        stdout, stderr = out.read().decode(), err.read().decode()
    if child.returncode != 0:
        raise RuntimeError(f"{' '.join(command)} (in {checkout}) failed: {stderr.strip()}")
    cpu = usage.ru_utime + usage.ru_stime
    return {"wall": wall, "cpu": cpu, "stdout": stdout, "stderr": stderr}


def bytecode_state(checkout: Path) -> tuple[int, int]:
    """(modules of ``checkout``'s imagemap with current bytecode, all its modules)."""
    sources = sorted((checkout / "imagemap").rglob("*.py"))
    current = 0
    for source in sources:
        cached = Path(importlib.util.cache_from_source(str(source)))
        current += cached.is_file() and cached.stat().st_mtime >= source.stat().st_mtime
    return current, len(sources)


def synthesis_args(class_dir: Path, out: Path) -> list[str]:
    depth = sorted((class_dir / "holdout").glob("*_depth.png"))[0]
    return ["synthesize", str(depth), "--db", str(class_dir), "-o", str(out)] + [
        "--preset", "fish", "--m", "2",
    ]  # fmt: skip


def _import_seconds(importtime: str, excluded: set[str]) -> float:
    """Sum of the top-level imports' cumulative times in ``-X importtime`` output, the
    ``excluded`` modules' left out."""
    total = 0
    for line in importtime.splitlines():
        found = re.match(r"import time:\s+\d+ \|\s+(\d+) \| (\S.*)$", line)
        if found and found.group(2).strip() not in excluded:  # depth 0: no indent
            total += int(found.group(1))
    return total / 1e6


def record(checkout: Path, class_dir: Path, work: Path) -> dict:
    """The untimed synthesis that writes the floor's plan, and its breakdown."""
    plan_path = work / f"plan_{_tag(checkout)}.json"
    out = work / f"record_{_tag(checkout)}.png"
    command = [sys.executable, "-X", "importtime", "-c", RECORD_CHILD, str(plan_path)]
    spawned = time.time()
    done = timed(command + synthesis_args(class_dir, out) + ["-v"], checkout)
    plan = json.loads(plan_path.read_text())
    found = re.search(r"^wrote .* in ([0-9.]+) s$", done["stderr"], re.M)
    during = {name for load in plan["kernels"] for name in load["new_modules"]}
    kernel_load = sum(load["seconds"] for load in plan["kernels"])
    # The pipeline's own work: its time less the kernels loaded and the modules imported
    # in it (the -X importtime lines between the estimate that -v logs just before it
    # and its "wrote" line; stderr keeps their order).
    inside = re.search(r"^imagemap: estimate .*?^wrote ", done["stderr"], re.M | re.S)
    pipeline = float(found.group(1)) if found else float("nan")
    pipeline -= kernel_load + _import_seconds(inside.group(0) if inside else "", during)
    parts = {
        "interpreter": plan["start"] - spawned,
        "imports": _import_seconds(done["stderr"], during),
        "kernel_load": kernel_load,
        "pipeline_work": pipeline,
    }
    parts["rest"] = done["wall"] - sum(parts.values())
    return {
        "plan": plan_path,
        "breakdown": parts,
        "wall": done["wall"],
        "kernels": [(k["name"], k["seconds"]) for k in plan["kernels"]],
        "modules": len(plan["modules"]),
    }


def floor(checkout: Path, plan: Path) -> dict:
    """One fresh floor process (:data:`FLOOR_CHILD`) of ``checkout`` with the ``plan`` that
    :func:`record` wrote: its wall and CPU seconds, the imports' and the kernel load's
    seconds timed inside it, and its peak RSS (MB, ``VmHWM``; NaN off Linux)."""
    done = timed([sys.executable, "-c", FLOOR_CHILD, str(plan)], checkout)
    inside = json.loads(done["stdout"])
    return {"seconds": done["wall"], "cpu_seconds": done["cpu"], **inside}


def _tag(checkout: Path) -> str:
    return hashlib.sha1(str(checkout).encode()).hexdigest()[:8]


def output_digest(out: Path) -> str:
    """SHA-256 over every file the synthesis wrote beside ``out`` (the map and companions)."""
    digest = hashlib.sha256()
    for path in sorted(out.parent.glob(out.stem + "*")):
        digest.update(path.name.replace(out.stem, "OUT").encode() + path.read_bytes())
    return digest.hexdigest()


def cases(checkout: Path, plan: Path, class_dir: Path, work: Path) -> dict[str, list[str]]:
    py = sys.executable
    out = work / f"synth_{_tag(checkout)}" / "map.png"
    out.parent.mkdir(exist_ok=True)
    return {
        "python -S -c pass": [py, "-S", "-c", "pass"],
        "python -c pass": [py, "-c", "pass"],
        "imagemap --help": [py, "-m", "imagemap", "--help"],
        "imagemap synthesize --help": [py, "-m", "imagemap", "synthesize", "--help"],
        "floor (imports + kernel load, no work)": [py, "-c", FLOOR_CHILD, str(plan)],
        "synthesis": [py, "-m", "imagemap", *synthesis_args(class_dir, out), "-q"],
    }


def run(args: argparse.Namespace) -> dict:
    import run as bench_run  # deferred: start-up (the driver only; numpy and imagemap)

    checkouts = {"after": ROOT}
    if args.before:
        checkouts["before"] = Path(args.before).resolve()
    if args.compile_bytecode:
        for checkout in checkouts.values():
            subprocess.run(
                [sys.executable, "-m", "compileall", "-q", str(checkout / "imagemap")],
                check=True, stdout=subprocess.DEVNULL,
            )  # fmt: skip
    width, height = (int(v) for v in args.size.split("x"))
    class_dir = bench_run.fish_class(Path(args.data), (width, height))
    report: dict = {"size": args.size, "reps": args.reps, "load_start": os.getloadavg()[0]}
    with tempfile.TemporaryDirectory() as scratch:
        work = Path(scratch)
        for path in checkouts.values():  # numba's cache, before anything is timed
            timed([sys.executable, "-m", "imagemap", *synthesis_args(class_dir, work / "warm.png")]
                  + ["-q"], path)  # fmt: skip
        recorded = {name: record(path, class_dir, work) for name, path in checkouts.items()}
        table = {
            name: cases(path, recorded[name]["plan"], class_dir, work)
            for name, path in checkouts.items()
        }
        runs = [(name, case) for case in table["after"] for name in checkouts]
        for name, case in runs:  # warm-up: the page cache, numba's index files
            timed(table[name][case], checkouts[name])
        times: dict = {name: {case: [] for case in table[name]} for name in checkouts}
        floor_parts: dict = {name: [] for name in checkouts}
        for rep in range(args.reps):
            for name, case in runs if rep % 2 == 0 else runs[::-1]:
                done = timed(table[name][case], checkouts[name])
                times[name][case].append((done["wall"], done["cpu"]))
                if case.startswith("floor"):
                    floor_parts[name].append(json.loads(done["stdout"]))
            print(f"repetition {rep + 1}/{args.reps} done, load {os.getloadavg()[0]:.2f}",
                  file=sys.stderr)  # fmt: skip
        digests = {
            name: output_digest(work / f"synth_{_tag(path)}" / "map.png")
            for name, path in checkouts.items()
        }
    report["load_end"] = os.getloadavg()[0]
    for name, path in checkouts.items():
        current, total = bytecode_state(path)
        report[name] = {
            "checkout": str(path),
            "bytecode": f"{current} of {total}",
            "cases": {
                case: {
                    "wall": statistics.median(w for w, _ in values),
                    "cpu": statistics.median(c for _, c in values),
                    "walls": [w for w, _ in values],
                    "cpus": [c for _, c in values],
                }
                for case, values in times[name].items()
            },
            "floor_parts": {
                key: statistics.median(part[key] for part in floor_parts[name])
                for key in ("imports", "kernel_load")
            },
            "record": {k: v for k, v in recorded[name].items() if k != "plan"},
            "output_sha256": digests[name],
        }
    if "before" in checkouts:
        report["identical_outputs"] = digests["after"] == digests["before"]
    return report


def format_report(report: dict) -> str:
    names = [name for name in ("after", "before") if name in report]
    lines = [
        f"fresh processes, median of {report['reps']} (interleaved); wall s (CPU s); "
        f"load {report['load_start']:.2f} -> {report['load_end']:.2f}",
        "",
    ]
    header = "| case | " + " | ".join(f"{n} s" for n in names) + " | above `python -c pass` |"
    if len(names) == 2:
        header += " after / before: wall, CPU (median of the repetitions' ratios; range) |"
    lines += [header, "|---" + "|---:" * (len(names) + 1 + (len(names) == 2)) + "|"]
    bare = {n: report[n]["cases"]["python -c pass"]["wall"] for n in names}
    for case in report["after"]["cases"]:
        cells = [
            f"{report[n]['cases'][case]['wall']:.3f} ({report[n]['cases'][case]['cpu']:.3f})"
            for n in names
        ]
        above = " / ".join(f"{report[n]['cases'][case]['wall'] - bare[n]:+.3f}" for n in names)
        row = f"| {case} | " + " | ".join(cells) + f" | {above} |"
        if len(names) == 2:
            after, before = report["after"]["cases"][case], report["before"]["cases"][case]
            cells = []
            for key in ("walls", "cpus"):
                ratios = [a / b for a, b in zip(after[key], before[key], strict=True)]
                cells.append(
                    f"×{statistics.median(ratios):.2f} ({min(ratios):.2f}–{max(ratios):.2f})"
                )
            row += f" {', '.join(cells)} |"
        lines.append(row)
    lines.append("")
    for n in names:
        info = report[n]
        parts = info["floor_parts"]
        rec = info["record"]
        breakdown = ", ".join(f"{k} {v:.3f}" for k, v in rec["breakdown"].items())
        kernels = ", ".join(f"{name} {s:.3f}" for name, s in rec["kernels"])
        lines += [
            f"{n} ({info['checkout']}): bytecode {info['bytecode']} modules; floor inside: "
            f"imports {parts['imports']:.3f} s, kernel load {parts['kernel_load']:.3f} s",
            f"  one synthesis with -X importtime ({rec['wall']:.3f} s): {breakdown}",
            f"  {len(rec['kernels'])} kernels loaded: {kernels}; {rec['modules']} modules",
            f"  output sha256 {info['output_sha256'][:16]}",
        ]
    if "identical_outputs" in report:
        lines.append(f"outputs byte-identical: {report['identical_outputs']}")
    return "\n".join(lines)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        description=__doc__.split("\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--reps", type=int, default=5, help="fresh processes per case")
    parser.add_argument("--size", default="200x150", help="the synthesis's size, WxH")
    parser.add_argument("--before", help="a second checkout, measured interleaved")
    parser.add_argument(
        "--compile-bytecode", action="store_true", help="write each checkout's bytecode first"
    )
    parser.add_argument(
        "--data", default=str(BENCHMARKS / ".data"), help="where the generated fish are kept"
    )
    parser.add_argument("--json", help="write every figure here")
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    report = run(args)
    print(format_report(report))
    if args.json:
        Path(args.json).write_text(json.dumps(report, indent=1, default=str))
    return 0


if __name__ == "__main__":
    sys.exit(main())
