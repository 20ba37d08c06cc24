"""``imagemap bench``: the speed and memory benchmarks of ``benchmarks/run.py``.

The benchmark script lives in the source checkout (``benchmarks/run.py``), not in
the installed package: this command runs that file with the same options, so the
figures of ``python benchmarks/run.py`` and ``imagemap bench`` are the same run.
"""

from __future__ import annotations

import argparse
import importlib.util
import sys
from pathlib import Path
from types import ModuleType

from imagemap.io import InputError

BENCH_HELP = """\
Speed and memory benchmarks: wall time, peak resident memory and tracemalloc
peak of depth-map colorization (200x150, 512x512, 1024x1024), BTF pixel-wise
extrapolation (R = 0, 1, 2) and texture optimization (128 -> 512), for each
search backend; the first call's JIT / cache-load time; a fresh 'imagemap
synthesize' process; with --quality the leave-one-out CIEDE2000 of a fish class.
Prints a Markdown table and writes it as JSON. Generated data is cached under
benchmarks/.data/.

Needs a source checkout (benchmarks/run.py beside the imagemap package).

examples:
  imagemap bench --quick
  imagemap bench --only colorize --backends patchmatch,exact
  imagemap bench --only quality
"""

SCRIPT = Path(__file__).resolve().parents[2] / "benchmarks" / "run.py"


def load_script(path: Path = SCRIPT) -> ModuleType:
    """Import ``benchmarks/run.py`` as a module.

    Raises
    ------
    InputError
        If the checkout has no ``benchmarks/run.py`` (an installed wheel).
    """
    if not path.is_file():
        raise InputError(f"{path}: not found; 'imagemap bench' needs a source checkout")
    name = "imagemap_benchmarks_run"
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    # Registered before it runs: dataclasses look their module up in sys.modules.
    sys.modules[name] = module
    try:
        spec.loader.exec_module(module)
    except BaseException:
        del sys.modules[name]
        raise
    return module


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "bench",
        help="speed and memory benchmarks (table + JSON)",
        description=BENCH_HELP,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    try:
        load_script().build_parser(p)
    except Exception as exc:  # a broken or missing script must not break the other commands
        error = str(exc)

        def unavailable(args: argparse.Namespace) -> int:
            raise InputError(f"imagemap bench is unavailable: {error}")

        p.set_defaults(func=unavailable)
        return
    p.set_defaults(func=run_bench)


def run_bench(args: argparse.Namespace) -> int:
    script = load_script()
    report = script.run(args)
    print(script.format_report(report))
    print(f"\n(written to {args.json}; {report['seconds']:.0f} s in all)")
    return 0
