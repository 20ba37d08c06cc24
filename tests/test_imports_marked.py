"""Function-level imports are there for a reason, and say which (issue #33, item 5).

An ``import`` inside a function is allowed only where start-up time (``imagemap --help``
and ``import imagemap`` load no NumPy) or an optional dependency needs it. Each says so:
a trailing comment ``# deferred: <why>`` on the import line, or, in a module whose
command functions all defer their imports (the CLI modules), a module-level constant
``DEFERRED_IMPORTS = "<why>"`` stating the rule once.
"""

from __future__ import annotations

import ast
import io
import tokenize
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "imagemap"
MARKER = "# deferred:"


def _declares_deferred_imports(tree: ast.Module) -> bool:
    """Whether the module assigns a non-empty string to ``DEFERRED_IMPORTS`` at its top."""
    for node in tree.body:
        targets = (
            node.targets
            if isinstance(node, ast.Assign)
            else [node.target]
            if isinstance(node, ast.AnnAssign)
            else []
        )
        value = getattr(node, "value", None)
        if (
            any(isinstance(t, ast.Name) and t.id == "DEFERRED_IMPORTS" for t in targets)
            and isinstance(value, ast.Constant)
            and isinstance(value.value, str)
            and value.value.strip()
        ):
            return True
    return False


def _marked_lines(source: str) -> set[int]:
    """Lines carrying a ``# deferred: <why>`` comment with a non-empty reason."""
    lines = set()
    for token in tokenize.generate_tokens(io.StringIO(source).readline):
        if token.type == tokenize.COMMENT and token.string.startswith(MARKER):
            if token.string[len(MARKER) :].strip():
                lines.add(token.start[0])
    return lines


def _function_level_imports(tree: ast.Module) -> list[ast.Import | ast.ImportFrom]:
    """Every import statement inside a function (at any depth, methods and nested too)."""
    found = []
    for function in ast.walk(tree):
        if isinstance(function, (ast.FunctionDef, ast.AsyncFunctionDef)):
            for node in ast.walk(function):
                if isinstance(node, (ast.Import, ast.ImportFrom)):
                    found.append(node)
    # A nested function's imports are seen from each enclosing function: count each once.
    return sorted({id(n): n for n in found}.values(), key=lambda n: n.lineno)


def unmarked_imports(path: Path, root: Path = ROOT) -> list[str]:
    """``path:line`` (relative to ``root``) of each function-level import neither marked
    nor in a module that declares ``DEFERRED_IMPORTS``."""
    source = path.read_text()
    tree = ast.parse(source, filename=str(path))
    if _declares_deferred_imports(tree):
        return []
    marked = _marked_lines(source)
    relative = path.relative_to(root)
    # The marker may close any line of a multi-line import (the first or the last).
    return [
        f"{relative}:{node.lineno}"
        for node in _function_level_imports(tree)
        if not marked.intersection({node.lineno, node.end_lineno})
    ]


def test_every_function_level_import_says_why():
    unmarked = [where for path in sorted(PACKAGE.rglob("*.py")) for where in unmarked_imports(path)]
    assert not unmarked, (
        f"{len(unmarked)} function-level imports without '# deferred: <why>' (or move "
        "them to the module's top):\n" + "\n".join(unmarked)
    )


SAMPLE = """
import os

def a():
    import json  # deferred: start-up
    from math import pi
    return pi

class C:
    def m(self):
        import re  # deferred:
        def inner():
            from collections import (  # deferred: optional dependency
                OrderedDict,
            )
            from os import (
                path,
            )  # deferred: start-up
        return inner
"""


def test_the_check_finds_unmarked_and_empty_marks(tmp_path):
    tree = ast.parse(SAMPLE)
    assert [n.lineno for n in _function_level_imports(tree)] == [5, 6, 11, 13, 16]
    assert _marked_lines(SAMPLE) == {5, 13, 18}  # "# deferred:" with no reason does not count
    module = tmp_path / "probe.py"
    module.write_text(SAMPLE)
    # The top-level import is not reported; the marked ones (first or last line) are not.
    assert unmarked_imports(module, root=tmp_path) == ["probe.py:6", "probe.py:11"]
    module.write_text('DEFERRED_IMPORTS = "start-up: the command runs them"\n' + SAMPLE)
    assert unmarked_imports(module, root=tmp_path) == []
    module.write_text('DEFERRED_IMPORTS = ""\n' + SAMPLE)  # an empty reason declares nothing
    assert len(unmarked_imports(module, root=tmp_path)) == 2
