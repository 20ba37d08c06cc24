"""``imagemap bench``: the speed and memory benchmarks of ``benchmarks/run.py``.

The benchmark script lives in the source checkout (``benchmarks/run.py``), not in
the installed package: this command runs that file with the same options, so the
figures of ``python benchmarks/run.py`` and ``imagemap bench`` are the same run.
The script is located and loaded only when ``imagemap bench`` runs (its options,
``--help`` included, are the script's own): no other command depends on it, and
without a checkout ``imagemap bench`` says so.
"""

from __future__ import annotations

import argparse
import importlib.util
import sys
from pathlib import Path
from types import ModuleType

from imagemap.errors import InputError

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


def load_script(path: Path | None = None) -> ModuleType:
    """Import ``benchmarks/run.py`` (or ``path``) as a module.

    Raises
    ------
    InputError
        If the checkout has no ``benchmarks/run.py`` (an installed wheel).
    """
    path = SCRIPT if path is None else Path(path)
    if not path.is_file():
        raise InputError(
            f"{path}: not found; 'imagemap bench' runs the benchmark script of a source "
            "checkout (benchmarks/run.py beside the imagemap package): run it from a clone "
            "of the repository installed with 'pip install -e .'"
        )
    name = "imagemap_benchmarks_run"
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or spec.loader is None:
        raise InputError(f"{path}: cannot be loaded as a Python module")
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
    # No options of its own (not even -h): everything after 'bench' goes to the
    # script's parser when the command runs (see imagemap.cli.main).
    p = subparsers.add_parser(
        "bench",
        help="speed and memory benchmarks (table + JSON; needs a source checkout)",
        add_help=False,
    )
    p.set_defaults(func=run_bench, forward_unknown=True)


def build_parser(script: ModuleType) -> argparse.ArgumentParser:
    """The script's options under the name ``imagemap bench``."""
    parser = argparse.ArgumentParser(
        prog="imagemap bench",
        description=BENCH_HELP,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    return script.build_parser(parser)


def run_bench(args: argparse.Namespace) -> int:
    script = load_script()
    try:
        options = build_parser(script).parse_args(getattr(args, "forwarded", []))
    except SystemExit as exc:
        if exc.code == 2:  # argparse printed the error naming the option
            return 2
        raise  # --help
    report = script.run(options)
    print(script.format_report(report))
    print(f"\n(written to {options.json}; {report['seconds']:.0f} s in all)")
    return 0
