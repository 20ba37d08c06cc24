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


@pytest.fixture(scope="module")
def package_graph() -> dict[str, set[str]]:
    """The package's import graph, parsed once for the tests below (1.5 s a parse)."""
    return import_graph()


def test_no_import_circle(package_graph):
    assert cycles(package_graph) == []


def test_data_gen_uses_imagemap_never_the_reverse(package_graph):
    graph = package_graph
    offenders = {m: sorted(t for t in ts if t.startswith("data_gen")) for m, ts in graph.items()}
    assert {m: ts for m, ts in offenders.items() if ts} == {}


#: The package's layers, bottom first: a module imports only from its own layer or
#: below (at run time, at any depth of its code). Within a layer, no circle.
LAYERS: tuple[tuple[str, ...], ...] = (
    # What everything uses: errors, argument checks, files, progress, previews. The
    # package root is a lazy facade (it imports nothing at run time).
    ("imagemap", "imagemap.errors", "imagemap.validate", "imagemap.progress",
     "imagemap.memory", "imagemap.io", "imagemap.align", "imagemap.render",
     "imagemap.outputs"),
    # The generic engine: guide and appearance bands, nothing of depth maps or meshes.
    ("imagemap.core",),
    # Examples as data, the PBR maps they carry, and the tangent frames of normal maps.
    ("imagemap.example", "imagemap.materials", "imagemap.tangents"),
    # Meshes, views, ray casting, mesh files: below the database, which reads them.
    ("imagemap.scene",),
    ("imagemap.database",),
    # The front ends on the engine (independent of each other: see below).
    ("imagemap.depth", "imagemap.btf"),
    # The mesh front end stands on the depth front end (views) and the scene.
    ("imagemap.mesh",),
    # What runs front ends on many objects: the evaluation, its measures and report,
    # batches.
    ("imagemap.metrics", "imagemap.report", "imagemap.evaluation", "imagemap.batch"),
    # The command line and the Blender add-on's packaging.
    ("imagemap.cli", "imagemap.__main__", "imagemap.blender"),
)  # fmt: skip

#: Layers that must not import each other.
INDEPENDENT = (("imagemap.depth", "imagemap.btf"),)


def layer_of(module: str) -> int:
    """The index in :data:`LAYERS` of the longest prefix naming ``module``'s layer."""
    best, found = -1, None
    for index, names in enumerate(LAYERS):
        for name in names:
            if (module == name or module.startswith(name + ".")) and len(name) > best:
                best, found = len(name), index
    if found is None:
        raise KeyError(f"{module} is in no layer of LAYERS: add it")
    return found


def arrows_up(graph: dict[str, set[str]]) -> list[tuple[str, str]]:
    """(importer, imported) pairs where a module imports from a layer above its own."""
    return sorted(
        (module, target)
        for module, targets in graph.items()
        for target in targets
        if target.startswith("imagemap") and layer_of(target) > layer_of(module)
    )


def test_the_layer_check_finds_an_arrow_up(tmp_path):
    """The check below could fail: core importing the database is found, the reverse not."""
    package = tmp_path / "imagemap"
    (package / "core").mkdir(parents=True)
    (package / "__init__.py").write_text("")
    (package / "core" / "__init__.py").write_text("")
    (package / "core" / "engine.py").write_text("from imagemap.database import Database\n")
    (package / "database.py").write_text("import imagemap.core.engine\n")
    graph = import_graph(package)
    assert arrows_up(graph) == [("imagemap.core.engine", "imagemap.database")]


def test_every_module_is_in_a_layer(package_graph):
    for module in package_graph:
        layer_of(module)  # raises, naming the module, when it is in none


def test_layers_import_downwards_only(package_graph):
    assert arrows_up(package_graph) == []


@pytest.mark.parametrize("first, second", INDEPENDENT)
def test_independent_front_ends_do_not_import_each_other(package_graph, first, second):
    graph = package_graph
    wrong = sorted(
        (module, target)
        for module, targets in graph.items()
        for target in targets
        for a, b in ((first, second), (second, first))
        if (module == a or module.startswith(a + "."))
        and (target == b or target.startswith(b + "."))
    )
    assert wrong == []
