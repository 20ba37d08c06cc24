"""The package's layout: no import circle, layers that only import downwards."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "imagemap"


def _module_name(path: Path, root: Path = PACKAGE) -> str:
    parts = path.relative_to(root.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _type_checking_blocks(tree: ast.AST) -> set[int]:
    """Ids of the import nodes inside ``if TYPE_CHECKING:`` (no import at run time)."""
    ids = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            ids.update(id(inner) for inner in ast.walk(node))
    return ids


def import_graph(root: Path = PACKAGE) -> dict[str, set[str]]:
    """Module -> the package modules it imports at run time (at any depth of the code)."""
    paths = {_module_name(p, root): p for p in sorted(root.rglob("*.py"))}
    graph: dict[str, set[str]] = {name: set() for name in paths}
    for name, path in paths.items():
        tree = ast.parse(path.read_text())
        skipped = _type_checking_blocks(tree)
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        for node in ast.walk(tree):
            if id(node) in skipped:
                continue
            targets: list[str] = []
            if isinstance(node, ast.Import):
                targets = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                    base = ".".join(anchor + ([base] if base else []))
                targets = [base] + [f"{base}.{alias.name}" for alias in node.names]
            for target in targets:
                if target in paths and target != name:
                    graph[name].add(target)
                elif target.startswith("data_gen"):
                    graph[name].add(target)
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    counter = [0]

    def visit(node: str) -> None:
        index[node] = low[node] = counter[0]
        counter[0] += 1
        stack.append(node)
        on_stack.add(node)
        for other in sorted(graph.get(node, ())):
            if other not in graph:
                continue
            if other not in index:
                visit(other)
                low[node] = min(low[node], low[other])
            elif other in on_stack:
                low[node] = min(low[node], index[other])
        if low[node] == index[node]:
            component = []
            while True:
                other = stack.pop()
                on_stack.discard(other)
                component.append(other)
                if other == node:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for node in sorted(graph):
        if node not in index:
            visit(node)
    return found


def test_the_cycle_finder_finds_a_circle(tmp_path):
    """The check below could fail: a two-module circle in a scratch package is found."""
    package = tmp_path / "imagemap"
    package.mkdir()
    (package / "__init__.py").write_text("")
    (package / "a.py").write_text("def f():\n    from imagemap import b\n")
    (package / "b.py").write_text("from imagemap.a import f\n")
    (package / "c.py").write_text(
        "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    import imagemap.a\n"
    )
    graph = import_graph(package)
    assert cycles(graph) == [["imagemap.a", "imagemap.b"]]
    assert "imagemap.a" not in graph["imagemap.c"]  # type-checking imports do not count


def test_no_import_circle():
    assert cycles(import_graph()) == []


def test_data_gen_uses_imagemap_never_the_reverse():
    graph = import_graph()
    offenders = {m: sorted(t for t in ts if t.startswith("data_gen")) for m, ts in graph.items()}
    assert {m: ts for m, ts in offenders.items() if ts} == {}


@pytest.mark.parametrize(
    "layer, forbidden",
    [
        # The generic engine knows nothing of depth maps, meshes, BTFs or the CLI.
        ("imagemap.core", ("imagemap.depth", "imagemap.mesh", "imagemap.btf", "imagemap.cli")),
        # The depth front end sits below meshes, batches and the CLI.
        ("imagemap.depth", ("imagemap.mesh.colorize", "imagemap.cli", "imagemap.btf")),
        ("imagemap.btf", ("imagemap.depth", "imagemap.mesh", "imagemap.cli")),
    ],
)
def test_layers_import_downwards_only(layer, forbidden):
    graph = import_graph()
    wrong = {
        module: sorted(t for t in targets if t.startswith(forbidden))
        for module, targets in graph.items()
        if module == layer or module.startswith(layer + ".")
    }
    assert {m: ts for m, ts in wrong.items() if ts} == {}
