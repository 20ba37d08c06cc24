"""Start-up: lazy package imports, a parser that imports nothing heavy, ``imagemap bench``."""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

import imagemap
from imagemap.cli import (
    APPEARANCE_PYRAMID_NAMES,
    BACKEND_NAMES,
    METHOD_NAMES,
    PRESET_NAMES,
    build_parser,
    main,
)

ROOT = Path(__file__).resolve().parents[1]
HEAVY = ("numpy", "scipy", "skimage", "sklearn", "numba", "pynndescent", "imageio", "trimesh")


def _modules_after(code: str, *, top_level: bool = True) -> set[str]:
    """Modules (top-level names unless ``top_level`` is false) loaded by ``code`` in a
    fresh interpreter using this checkout."""
    probe = f"{code}\nimport json, sys\nprint(json.dumps(sorted(sys.modules)))"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    out = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, check=True, env=env
    ).stdout
    names = json.loads(out.splitlines()[-1])
    return {name.split(".")[0] for name in names} if top_level else set(names)


def test_import_imagemap_loads_nothing_heavy():
    assert not _modules_after("import imagemap").intersection(HEAVY)


def test_building_the_parser_loads_no_scientific_module():
    loaded = _modules_after("from imagemap.cli import build_parser; build_parser()")
    assert not loaded.intersection(HEAVY)


#: Runs ``imagemap ARGS`` as the program does (``python -m imagemap``), then the probe.
_PROGRAM = (
    "import runpy, sys\n"
    "sys.argv = ['imagemap', {args}]\n"
    "try:\n"
    "    runpy.run_module('imagemap', run_name='__main__')\n"
    "except SystemExit:\n"
    "    pass\n"
)


def test_synthesize_help_imports_no_scientific_module_and_no_other_command():
    # #44 item 1: `imagemap synthesize --help` within a few ms of bare Python. It prints
    # its help having imported no scientific module, not the configuration's dataclasses
    # (imagemap.depth.config: 15 ms) and no other command's module.
    loaded = _modules_after(_PROGRAM.format(args="'synthesize', '--help'"), top_level=False)
    assert not {name.split(".")[0] for name in loaded}.intersection(HEAVY)
    assert "imagemap.cli.synthesize" in loaded  # the probe ran the command's parser
    assert not loaded.intersection({"imagemap.depth.config", "imagemap.core.params"})
    others = {"imagemap.cli.btf", "imagemap.cli.evaluate", "imagemap.cli.batch"}
    assert not loaded.intersection(others)


def test_each_command_is_registered_by_the_module_commands_names():
    # COMMANDS says which module registers each command: `imagemap COMMAND` builds that
    # module's parsers alone. Every command of the whole parser is in the table, and
    # each module's parser has exactly the commands the table gives it.
    from imagemap.cli import COMMANDS, SUBCOMMAND_MODULES

    def commands(parser):
        (action,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
        return set(action.choices)

    assert commands(build_parser()) == set(COMMANDS)
    assert set(COMMANDS.values()) == set(SUBCOMMAND_MODULES)
    for command, module in COMMANDS.items():
        assert commands(build_parser(command)) == {c for c, m in COMMANDS.items() if m == module}


def test_one_commands_parser_reads_a_command_line_as_the_whole_parser_does(capsys):
    argv = ["synthesize", "q_depth.png", "--db", "db", "-o", "out.png", "--m", "3", "--vote",
            "mean", "--no-mirror", "--seed", "7"]  # fmt: skip
    whole, alone = (vars(build_parser(c).parse_args(argv)) for c in (None, "synthesize"))
    assert alone == whole and alone["m"] == 3 and alone["mirror"] is False
    assert main(["synthesise", "q_depth.png"]) == 2  # an unknown command lists them all
    error = capsys.readouterr().err
    assert "invalid choice: 'synthesise'" in error and "'btf'" in error and "'batch'" in error


def test_a_synthesis_does_not_import_scipy_signal_or_stats():
    # scipy.signal pulls in scipy.stats: 0.45 s and 33 MB of every fresh
    # `imagemap synthesize` for three FFT correlations (completion._correlate_valid).
    loaded = _modules_after(
        "import imagemap.cli, imagemap.depth.pipeline, imagemap.depth.completion",
        top_level=False,
    )
    assert "scipy.ndimage" in loaded  # the probe sees submodules
    assert not loaded.intersection({"scipy.signal", "scipy.stats", "scipy.cluster"})


@pytest.mark.parametrize(
    "module", ["imagemap.cli.synthesize", "imagemap.cli.evaluate", "imagemap.cli.bench"]
)
def test_registering_a_command_loads_not_even_numpy(module):
    code = (
        "import argparse, importlib\n"
        f"importlib.import_module({module!r}).register("
        "argparse.ArgumentParser().add_subparsers())"
    )
    assert not _modules_after(code).intersection(HEAVY)


def test_public_names_are_importable_and_lazy_submodules_resolve():
    from imagemap import Database, InputError, colorize  # noqa: F401

    assert set(imagemap.__all__) <= set(dir(imagemap))
    for name in imagemap.__all__:
        assert getattr(imagemap, name) is not None
    assert imagemap.InputError is imagemap.io.InputError
    with imagemap.depth.budget.memory_check(False):  # a submodule, reached as an attribute
        pass
    with pytest.raises(AttributeError, match="no_such_thing"):
        imagemap.no_such_thing  # noqa: B018


def test_option_choices_match_the_library():
    from imagemap.core.engine import APPEARANCE_PYRAMIDS, BACKENDS
    from imagemap.depth.config import METHODS, PRESETS

    assert PRESET_NAMES == tuple(sorted(PRESETS))
    assert BACKEND_NAMES == tuple(BACKENDS)
    assert METHOD_NAMES == tuple(METHODS)
    assert APPEARANCE_PYRAMID_NAMES == APPEARANCE_PYRAMIDS


def test_version_has_one_source(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0
    assert capsys.readouterr().out.strip() == f"imagemap {imagemap.__version__}"
    pyproject = (ROOT / "pyproject.toml").read_text()
    assert 'dynamic = ["version"]' in pyproject or "\nversion = " in pyproject


def test_unknown_arguments_are_still_refused(capsys):
    assert main(["db", "check", "somewhere", "--bogus"]) == 2
    assert "unrecognized arguments: --bogus" in capsys.readouterr().err


def test_bench_help_is_the_scripts(capsys):
    if not (ROOT / "benchmarks" / "run.py").is_file():
        pytest.skip("no benchmarks/run.py checkout")
    with pytest.raises(SystemExit) as exc:
        main(["bench", "--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    assert "imagemap bench" in out and "--quick" in out and "examples:" in out
    assert main(["bench", "--no-such-option"]) == 2
    assert "--no-such-option" in capsys.readouterr().err


def test_without_the_benchmark_script_only_bench_fails(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr("imagemap.cli.bench.SCRIPT", tmp_path / "benchmarks" / "run.py")
    monkeypatch.delitem(sys.modules, "imagemap_benchmarks_run", raising=False)
    build_parser()  # every other command builds and runs without it
    with pytest.raises(SystemExit):
        main(["evaluate", "--help"])
    capsys.readouterr()
    assert main(["bench", "--quick"]) == 2
    err = capsys.readouterr().err
    assert "run.py: not found" in err and "source checkout" in err


def test_the_startup_benchmark_counts_top_level_imports_only():
    # benchmarks/startup.py's breakdown: the top-level imports' cumulative times (a nested
    # import is inside its parent's), those numba made while loading a kernel left out.
    import importlib.util

    path = ROOT / "benchmarks" / "startup.py"
    if not path.is_file():
        pytest.skip("no benchmarks/startup.py checkout")
    spec = importlib.util.spec_from_file_location("imagemap_benchmarks_startup", path)
    startup = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(startup)
    text = (
        "import time: self [us] | cumulative | imported package\n"
        "import time:       100 |        100 |   numpy.core\n"
        "import time:       200 |        300 | numpy\n"
        "imagemap: a log line between the imports\n"
        "import time:        50 |         50 | numba.np.arraymath\n"
        "import time:        25 |       1000 | scipy\n"
    )
    assert startup._import_seconds(text, set()) == pytest.approx(1350e-6)
    assert startup._import_seconds(text, {"numba.np.arraymath", "scipy"}) == pytest.approx(300e-6)


def test_a_folder_of_pictures_does_not_import_the_mesh_modules(tmp_path):
    # imagemap.scene (mesh examples: 30-45 ms of a fresh process's CPU) is imported for a
    # database folder only when it holds a mesh file.
    import numpy as np

    from imagemap.io import write_image

    depth = np.zeros((16, 24), np.float32)
    depth[4:12, 6:18] = 0.5
    np.save(tmp_path / "fish_000_depth.npy", depth)
    write_image(tmp_path / "fish_000_image.png", np.ones((16, 24, 3)))
    probe = (
        "import argparse, sys\n"
        "from imagemap.cli.mesh import is_mesh_request\n"
        "from imagemap.database import Database\n"
        "import imagemap.depth.pipeline\n"
        f"db = Database.from_directory({str(tmp_path)!r})\n"
        "request = argparse.Namespace(depth=['q_depth.png'], output='map.png')\n"
        "print(len(db), is_mesh_request(request), 'imagemap.scene' in sys.modules)\n"
        f"open({str(tmp_path / 'fish_001.glb')!r}, 'wb').close()\n"
        f"db = Database.from_directory({str(tmp_path)!r})\n"
        "print(len(db), 'imagemap.scene' in sys.modules)"
    )
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    out = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, check=True, env=env
    ).stdout.split()
    assert out == ["1", "False", "False", "2", "True"]


def test_a_synthesis_skips_the_optional_imports_no_part_of_it_uses():
    # numba looks for PyYAML: `imagemap synthesize` reports it missing while it imports.
    # SciPy's array-API layer reads every NumPy attribute, numpy.testing and numpy.f2py
    # among them, and numba imports importlib.metadata for its extensions: they are lazy,
    # so their code (f2py's Fortran parser, which looked for charset_normalizer;
    # numpy.testing's unittest; importlib.metadata's email) never runs, yet they work
    # when used.
    code = (
        "import os; os.chdir({!r})\n"  # no .numba_config.yaml here
        "from imagemap.cli import skip_optional_imports\n"
        "with skip_optional_imports(True):\n"
        "    import numba, scipy.ndimage\n"
        "import sys; unused = sorted(n for n in sys.modules if n.startswith(\n"
        "    ('yaml', 'charset_normalizer', 'numpy.f2py.', 'numpy.testing.', 'unittest')))\n"
        "print(unused)\n"
    ).format(str(ROOT / "imagemap"))
    loaded = _modules_after(code, top_level=False)
    lazy = {"numpy.testing", "numpy.f2py", "importlib.metadata"}
    assert {"numba", "scipy.ndimage"} | lazy <= loaded
    assert not {n for n in loaded if n.startswith(("yaml", "charset_normalizer", "unittest"))}
    assert not {n for n in loaded if n.startswith(tuple(f"{name}." for name in lazy))}
    assert "email" not in loaded
    used = _modules_after(
        code + "import numpy.testing\nnumpy.testing.assert_equal(1, 1)\n"
        "import importlib.metadata\nprint(importlib.metadata.version('numpy'))",
        top_level=False,
    )
    assert {"numpy.testing._private.utils", "importlib.metadata._meta"} <= used


def test_a_kernel_loaded_lean_gives_the_python_functions_answer():
    # `imagemap synthesize` links imagemap's cached kernels without numba's registries
    # (cli.lean_kernel_loads): the kernel's answer is its Python function's, and where
    # it came from the cache numba's lowering registries (its cffi support among them)
    # were not imported.
    code = (
        "import numpy as np\n"
        "from imagemap.cli import lean_kernel_loads\n"
        "from imagemap.core.kernels import nearest_host_distance as kernel\n"
        "lean = lean_kernel_loads()\n"
        "rng = np.random.default_rng(0)\n"
        "colours, host = rng.random((5, 6, 3), np.float32), rng.random((2, 3, 3), np.float32)\n"
        "cells = np.array([0, 0, 0, 1, 1], np.int64), np.array([0, 0, 1, 1, 2, 2], np.int64)\n"
        "got, want = kernel(colours, host, *cells), kernel.py_func(colours, host, *cells)\n"
        "import sys\n"
        "from numba.core import entrypoints\n"
        "hit = kernel.stats.cache_hits.most_common(1) != []\n"
        "registries = 'numba.misc.cffiimpl' in sys.modules\n"
        "scanned = entrypoints._already_initialized\n"
        "import numba\n"
        "other = numba.njit(lambda x: x + 1)(1) == 2 and entrypoints._already_initialized\n"
        "print(lean, np.array_equal(got, want), hit, registries, scanned, other)\n"
    )
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, env=env
    ).stdout.split()
    lean, same, from_cache, registries, scanned, other = (word == "True" for word in out[-6:])
    assert same
    assert other  # another function's first call: numba's extensions loaded, as always
    if lean and from_cache:
        assert not registries
        assert not scanned  # imagemap's kernel from the cache: no extension scan


def test_the_programs_lean_start_waits_for_numba(tmp_path):
    # `imagemap synthesize` as the program (main() without argv) starts lean
    # (cli.lean_start): a run stopped by bad input before the engine imports no numba,
    # and once numba is imported its kernels load lean (on the numba checked), the hook
    # gone and the optional imports still skipped.
    code = (
        "import os, sys\n"
        "os.chdir({root!r})\n"  # no .numba_config.yaml here
        "from imagemap.cli import LEAN_LOAD_NUMBA, lean_start, main\n"
        "sys.argv = ['imagemap', 'synthesize', {missing!r}, '--db', {db!r}, '-o', {out!r}]\n"
        "refused = main() == 2 and 'numba' not in sys.modules\n"
        "with lean_start(True) as start:\n"
        "    waiting = start.hooks[0] in sys.meta_path\n"
        "    import numba\n"
        "    from numba.core import caching\n"
        "    lean = getattr(caching.Cache.load_overload, 'imagemap_lean', False)\n"
        "checked = '.'.join(numba.__version__.split('.')[:2]) in LEAN_LOAD_NUMBA\n"
        "skipped = not {{'yaml', 'charset_normalizer'}} & set(sys.modules)\n"
        "print(refused, waiting, lean == checked, start.hooks[0] not in sys.meta_path, skipped)\n"
    ).format(
        root=str(ROOT / "imagemap"),
        missing=str(tmp_path / "missing_depth.png"),
        db=str(tmp_path),
        out=str(tmp_path / "out.png"),
    )
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, env=env
    ).stdout.split()
    assert out[-5:] == ["True"] * 5


def test_the_program_writes_the_map_of_the_in_process_call(tmp_path):
    # `imagemap synthesize` as its own process starts lean (cli.lean_start: optional
    # imports skipped, unused modules lazy, kernels linked lean): the map is byte for byte
    # the in-process call's, which changes none of that.
    import numpy as np

    from imagemap.cli import main as imagemap_main
    from imagemap.io import write_image
    from tests.conftest import PALETTE, blob, painted

    db = tmp_path / "db"
    db.mkdir()
    for i, (cy, cx) in enumerate([(24, 32), (23, 30)]):
        depth = blob(centre=(cy, cx), bumps=0.02, seed=i)
        np.save(db / f"blob_{i}_depth.npy", depth)
        write_image(db / f"blob_{i}_image.png", painted(depth, PALETTE))
    np.save(tmp_path / "q_depth.npy", blob(radii=(15, 25), bumps=0.02, seed=9))
    argv = ["synthesize", str(tmp_path / "q_depth.npy"), "--db", str(db), "--seed", "3", "-q"]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    subprocess.run(
        [sys.executable, "-m", "imagemap", *argv, "-o", str(tmp_path / "program.png")],
        check=True,
        env=env,
    )
    assert imagemap_main([*argv, "-o", str(tmp_path / "call.png")]) == 0
    assert (tmp_path / "program.png").read_bytes() == (tmp_path / "call.png").read_bytes()


_SCIPY_DOCS_PROBE = """
import ast, hashlib, inspect, json, sys
import numpy as np
import scipy._lib._docscrape as docscrape
from imagemap.cli import LEAN_DOCS_SCIPY, lean_start

parses = [0]
parse = docscrape.FunctionDoc.__init__
def counted(self, *args, **kwargs):
    parses[0] += 1
    return parse(self, *args, **kwargs)
docscrape.FunctionDoc.__init__ = counted

with lean_start({on}):
    import scipy.fft, scipy.linalg, scipy.ndimage, scipy.special
    import scipy._lib._array_api as array_api
imported = parses[0]
@array_api.xp_capabilities()
def later():
    '''A function SciPy decorates after the start.'''
source = ast.parse(open(scipy.linalg._basic.__file__).read())
solve_own = next(ast.get_docstring(node) for node in ast.walk(source)
                 if isinstance(node, ast.FunctionDef) and node.name == "solve_triangular")
table = array_api.xp_capabilities_table
rng = np.random.default_rng(0)
image, matrix = rng.random((40, 30)), rng.random((5, 5)) + 5 * np.eye(5)
outputs = (scipy.ndimage.gaussian_filter(image, 2.0), scipy.ndimage.median_filter(image, 5),
           scipy.linalg.solve(matrix, np.arange(5.0)), scipy.fft.dctn(image, norm="ortho"),
           scipy.special.erf(image))
print(json.dumps({{
    "checked": ".".join(scipy.__version__.split(".")[:2]) in LEAN_DOCS_SCIPY,
    "parses": imported,
    "notes": sum("Array API Standard" in (f.__doc__ or "") for f in table if f is not later),
    "table": sorted(f"{{getattr(f, '__module__', '')}}.{{f.__name__}}" for f in table),
    "gaussian_filter": scipy.ndimage.gaussian_filter in table,
    "solve_own": inspect.cleandoc(scipy.linalg.solve_triangular.__doc__) == solve_own,
    "later_note": "Array API Standard Support" in later.__doc__,
    "outputs": hashlib.sha256(b"".join(o.tobytes() for o in outputs)).hexdigest(),
}}))
"""


def test_a_synthesis_leaves_scipys_docstrings_as_they_are():
    # SciPy 1.17's decorators parse and re-render the docstring of each function they
    # decorate at import (numpydoc's FunctionDoc: an array-API note, a batch note).
    # `imagemap synthesize` (cli.lean_start) lets them keep their own docstrings: no
    # parse, the capabilities table filled all the same, the same results; afterwards
    # SciPy's notes come back. Without it SciPy is untouched.
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    runs = {}
    for on in (True, False):
        out = subprocess.run(
            [sys.executable, "-c", _SCIPY_DOCS_PROBE.format(on=on)],
            capture_output=True,
            text=True,
            check=True,
            env=env,
        ).stdout
        runs[on] = json.loads(out.splitlines()[-1])
    lean, standard = runs[True], runs[False]
    assert standard["parses"] > 250 and standard["notes"] == len(standard["table"]) - 1 > 200
    assert not standard["solve_own"] and standard["later_note"]
    assert lean["table"] == standard["table"] and lean["gaussian_filter"]
    assert lean["outputs"] == standard["outputs"]
    assert lean["later_note"]  # restored after the start
    if lean["checked"]:
        assert lean["parses"] == 0 and lean["notes"] == 0 and lean["solve_own"]
    else:
        assert lean["parses"] == standard["parses"]
