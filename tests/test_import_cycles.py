"""The package's import graph has no cycle: every ``import`` and ``from ... import`` of a holoslam module,
at module level or inside a function (a function-level import hides a cycle, it does not remove it), and
``TYPE_CHECKING`` imports too, is an edge from the importing module to the module it names."""

from __future__ import annotations

import ast
from pathlib import Path

import networkx as nx
from repo_paths import REPO

PACKAGE = REPO / "holoslam"


def _modules() -> dict[str, Path]:
    out = {}
    for p in PACKAGE.rglob("*.py"):
        parts = p.relative_to(PACKAGE.parent).with_suffix("").parts
        out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = p
    return out


def _targets(module: str, path: Path, node: ast.Import | ast.ImportFrom, modules: dict[str, Path]) -> list[str]:
    """The holoslam modules an import statement names (``from pkg import mod`` names pkg.mod)."""
    if isinstance(node, ast.Import):
        names = [a.name for a in node.names]
    else:
        if node.level:
            pkg = module.split(".") if path.name == "__init__.py" else module.split(".")[:-1]
            base = ".".join(pkg[: len(pkg) - node.level + 1] + ([node.module] if node.module else []))
        else:
            base = node.module or ""
        names = [f"{base}.{a.name}" if f"{base}.{a.name}" in modules else base for a in node.names]
    out = []
    for name in names:
        while name and name not in modules:
            name = name.rpartition(".")[0]
        if name.startswith("holoslam") and name != module:
            out.append(name)
    return out


def import_graph() -> nx.DiGraph:
    modules = _modules()
    graph = nx.DiGraph()
    graph.add_nodes_from(modules)
    for module, path in modules.items():
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import | ast.ImportFrom):
                graph.add_edges_from((module, t) for t in _targets(module, path, node, modules))
    return graph


def test_no_import_cycle_in_the_package():
    graph = import_graph()
    assert graph.number_of_nodes() > 100 and graph.number_of_edges() > 300  # the walk saw the package
    cycles = [sorted(c) for c in nx.strongly_connected_components(graph) if len(c) > 1]
    assert cycles == [], f"import cycles: {cycles}"


def test_the_graph_sees_function_level_imports():
    # sim.sensors renders its snapshots with a function-level import of sim.render: that edge must be seen
    assert import_graph().has_edge("holoslam.sim.sensors", "holoslam.sim.render")
