"""The package's import graph has no circle: every import inside compgen, at the top of a
module or inside a function, points one way (modules at the bottom never ask those above)."""

import ast
from pathlib import Path

from conftest import ROOT

PACKAGE = ROOT / "compgen"


def _module(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _graph() -> dict[str, set[str]]:
    modules = {_module(p): p for p in PACKAGE.rglob("*.py")}
    graph = {m: set() for m in modules}
    for name, path in modules.items():
        package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.ImportFrom):
                base = package
                for _ in range(node.level - 1):
                    base = base.rsplit(".", 1)[0]
                target = ((f"{base}.{node.module}" if node.module else base) if node.level
                          else node.module or "")
                for alias in node.names:     # `from . import motion` names a module
                    sub = f"{target}.{alias.name}"
                    graph[name].add(sub if sub in modules else target)
            elif isinstance(node, ast.Import):
                graph[name].update(a.name for a in node.names)
        graph[name] = {t for t in graph[name] if t in modules and t != name}
    return graph


def _circle(graph: dict[str, set[str]]) -> list[str] | None:
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(m):
        state[m] = 1
        stack.append(m)
        for t in sorted(graph[m]):
            if state.get(t) == 1:
                return [*stack[stack.index(t):], t]
            if t not in state and (found := visit(t)):
                return found
        stack.pop()
        state[m] = 2
        return None

    for m in sorted(graph):
        if m not in state and (found := visit(m)):
            return found
    return None


def test_the_import_graph_has_no_circle():
    circle = _circle(_graph())
    assert circle is None, " -> ".join(circle)


def test_the_graph_reader_sees_lazy_imports():
    """A function-local import is an arrow too (the reader must not miss the kind that
    made the old circle through machine.py)."""
    graph = _graph()
    assert "compgen.emit.registry" in graph["compgen.machine_file"]
    assert "compgen.emit.programs" in graph["compgen.advice"]
    assert "compgen.plots" in graph["compgen.cli"]          # imported inside a command
