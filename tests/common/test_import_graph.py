"""The import graph of our packages, read from the sources (ast): no cycles, node modules are leaves.

Imports inside functions count (a lazy import hides a cycle, it does not cut
it); imports under ``if TYPE_CHECKING:`` do not (they never run).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[2] / "src"


def _modules() -> dict[str, Path]:
    mods = {}
    for pkg_dir in sorted(SRC.glob("tactile_*/tactile_*")):
        if not (pkg_dir / "__init__.py").exists():
            continue
        for f in pkg_dir.rglob("*.py"):
            parts = f.relative_to(pkg_dir.parent).with_suffix("").parts
            mods[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = f
    return mods


def _type_checking_nodes(tree: ast.AST) -> set[int]:
    skip = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            skip.update(id(n) for stmt in node.body for n in ast.walk(stmt))
    return skip


def _imports(name: str, path: Path) -> set[str]:
    """Every module name ``name`` imports (``from a import b`` gives a and a.b)."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    tree = ast.parse(path.read_text(), str(path))
    skip = _type_checking_nodes(tree)
    out = set()
    for node in ast.walk(tree):
        if id(node) in skip:
            continue
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                module = ".".join(base + ([node.module] if node.module else []))
            else:
                module = node.module
            out.add(module)
            out.update(f"{module}.{a.name}" for a in node.names)
    return out


MODULES = _modules()
GRAPH = {name: {m for m in _imports(name, path) if m in MODULES and m != name} for name, path in MODULES.items()}


def _cycle_through(start: str):
    """One import path start → … → start, or None (iterative DFS)."""
    stack = [(start, [start])]
    seen = set()
    while stack:
        mod, path = stack.pop()
        for dep in GRAPH[mod]:
            if dep == start:
                return path + [start]
            if dep not in seen:
                seen.add(dep)
                stack.append((dep, path + [dep]))
    return None


def test_the_sources_were_found():
    assert {"tactile_common.topics", "tactile_bringup.progress", "tactile_bringup.loop"} <= set(MODULES)


@pytest.mark.parametrize("module", sorted(MODULES))
def test_no_import_cycle(module):
    cycle = _cycle_through(module)
    assert cycle is None, "import cycle: " + " -> ".join(cycle)


def _is_node_module(name: str) -> bool:
    last = name.rpartition(".")[2]
    return last == "node" or last.endswith("_node")


def test_node_modules_are_imported_by_no_other_module():
    """A node module is an entry point; a helper another package needs belongs in a core module."""
    offenders = sorted(f"{m} imports {d}" for m, deps in GRAPH.items() for d in deps if _is_node_module(d))
    assert not offenders, offenders
