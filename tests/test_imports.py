"""Layering: no module of the package imports (directly or through others) a module that imports it back,
and only the CLI parses arguments.

The graph is read from the source with ``ast``, including imports inside functions (a lazy import
still ties two modules together). Importing ``posecons.a.b`` also runs ``posecons/a/__init__.py``,
so that is an edge too, unless the package is an ancestor of the importer (already initialised).
"""

from __future__ import annotations

import ast
from collections.abc import Callable
from pathlib import Path

SRC = Path(__file__).resolve().parents[1] / "src"


def _module_name(path: Path) -> str:
    parts = path.relative_to(SRC).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imports() -> dict[str, set[str]]:
    """The modules each module of the package imports, by absolute name (the standard library's too)."""
    files = {_module_name(p): p for p in (SRC / "posecons").rglob("*.py")}
    imports: dict[str, set[str]] = {name: set() for name in files}
    for name, path in files.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                imports[name].update(alias.name for alias in node.names)
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                    base = ".".join(anchor + ([base] if base else []))
                # `from pkg import sub` imports the submodule pkg.sub when there is one
                imports[name].update(f"{base}.{a.name}" if f"{base}.{a.name}" in files else base for a in node.names)
    return imports


def _import_graph() -> dict[str, set[str]]:
    imports = _imports()
    graph: dict[str, set[str]] = {name: set() for name in imports}
    for name, targets in imports.items():
        for target in targets:
            parts = target.split(".")
            for i in range(1, len(parts) + 1):
                module = ".".join(parts[:i])
                is_ancestor = name == module or name.startswith(module + ".")
                if module in imports and not is_ancestor:
                    graph[name].add(module)
    return graph


def _find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    state: dict[str, int] = {}  # 1: on the current path, 2: done
    path: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        path.append(node)
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 1:
                return path[path.index(nxt) :] + [nxt]
            if nxt not in state and (cycle := visit(nxt)):
                return cycle
        state[node] = 2
        path.pop()
        return None

    for start in sorted(graph):
        if start not in state and (cycle := visit(start)):
            return cycle
    return None


def test_the_graph_sees_the_package():
    graph = _import_graph()
    assert "posecons.cli.demo" in graph and "posecons.config" in graph["posecons.cli.demo"]
    assert "posecons.inference.backend" in graph["posecons.evaluation.evaluate"]


def test_no_module_imports_one_that_imports_it_back():
    cycle = _find_cycle(_import_graph())
    assert cycle is None, "import cycle: " + " → ".join(cycle)


def test_core_maths_import_no_file_formats_plots_or_commands():
    graph = _import_graph()
    for core in ("posecons.metrics.depth", "posecons.metrics.pose", "posecons.geometry"):
        assert graph[core] <= {"posecons.errors"}, (core, graph[core])


def _in(module: str, package: str) -> bool:
    return module == package or module.startswith(package + ".")


def _banned(edges: dict[str, set[str]], importer: Callable[[str], bool], banned: tuple[str, ...]) -> list[str]:
    """Each edge of ``edges`` from an ``importer`` module into a ``banned`` package, as "A imports B"."""
    return [
        f"{name} imports {target}"
        for name in sorted(edges)
        if importer(name)
        for target in sorted(edges[name])
        if any(_in(target, package) for package in banned)
    ]


def test_only_the_cli_parses_arguments_or_imports_the_cli():
    """The CLI sits on top: argparse and ``posecons.cli`` are imported in ``posecons.cli`` only. Caught
    mutations: ``import argparse`` in study/worker.py; ``from ..cli.arguments import positive_int`` in
    training/trainer.py."""
    wrong = _banned(_imports(), lambda name: not _in(name, "posecons.cli"), ("argparse", "posecons.cli"))
    assert not wrong, "; ".join(wrong)


def test_training_imports_no_evaluation_or_inference():
    """Training sits below evaluation and inference; the demo, which runs all three, is the CLI's.
    Caught mutation: ``from ..evaluation import evaluate`` in training/trainer.py."""
    wrong = _banned(
        _import_graph(), lambda name: _in(name, "posecons.training"), ("posecons.evaluation", "posecons.inference")
    )
    assert not wrong, "; ".join(wrong)
