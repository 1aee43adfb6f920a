"""The package's import graph has no circle: every import inside compgen, at the top of a
module or inside a function, points one way (modules at the bottom never ask those above)."""

import ast
from pathlib import Path

from conftest import ROOT

PACKAGE = ROOT / "compgen"


def _module(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _nodes(tree: ast.AST, types: bool):
    """Every node; without ``types``, none under ``if TYPE_CHECKING:`` (a type's name for
    the reader, no import when the module runs)."""
    todo = [tree]
    while todo:
        node = todo.pop()
        yield node
        for child in ast.iter_child_nodes(node):
            if types or not (isinstance(child, ast.If) and isinstance(child.test, ast.Name)
                             and child.test.id == "TYPE_CHECKING"):
                todo.append(child)


def _graph(types: bool = False) -> dict[str, set[str]]:
    """Each module of compgen → the modules it imports when it runs (with ``types``, also
    those it names for a type checker only)."""
    modules = {_module(p): p for p in PACKAGE.rglob("*.py")}
    graph = {m: set() for m in modules}
    for name, path in modules.items():
        package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
        for node in _nodes(ast.parse(path.read_text(), str(path)), types):
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
    assert "compgen.controllers.registry" in graph["compgen.configuration.machine_file"]
    assert "compgen.controllers.programs" in graph["compgen.planning.advice"]
    assert "compgen.reports.plots" in graph["compgen.commands.cli"]      # imported inside a command


def _reach(graph: dict[str, set[str]], start: str) -> set[str]:
    seen, todo = set(), [start]
    while todo:
        for t in graph[todo.pop()] - seen:
            seen.add(t)
            todo.append(t)
    return seen


def test_the_statistics_load_no_controller_program_motion_store_or_history():
    """The fit and diagnose are statistics on the model and the data: the measurements they
    advise are checked by an advisor their caller passes in (``advice.Advisor``, which
    writes programs), so importing them, at the top or inside any function, reaches none
    of the layers above."""
    graph = _graph()
    above = tuple(f"compgen.{folder}" for folder in LAYERS[LAYERS.index("statistics") + 1:])
    for statistics in (m for m in graph if m.startswith("compgen.statistics")):
        up = sorted(m for m in _reach(graph, statistics) if m.startswith(above))
        assert not up, f"{statistics} reaches {up}"


def test_the_graph_reader_tells_type_only_imports():
    """results names ``Machine`` for its readers under ``if TYPE_CHECKING:``: an arrow of
    the typed graph only; the reader sees the others in both."""
    runs, typed = _graph()["compgen.statistics.results"], _graph(types=True)["compgen.statistics.results"]
    assert "compgen.model.machine" in typed - runs and "compgen.errors" in runs & typed


# The package's floor plan, lowest first: each layer is a folder of compgen (the modules at
# its top are the base; ``python -m compgen`` runs the commands), and a module imports only
# from its own layer or those below (docs/layout.md draws it). The statistics take their
# advisor from their caller; a machine file names its control, so configuration sits above.
LAYERS = ["base", "model", "data", "statistics", "motion", "controllers", "configuration", "planning",
          "history", "reports", "commands"]


def _layer(module: str) -> str:
    if module == "compgen.__main__":
        return "commands"
    parts = module.split(".")
    return parts[1] if len(parts) > 2 or (len(parts) == 2 and parts[1] in LAYERS) else "base"


def _arrows_up(graph: dict[str, set[str]]) -> list[str]:
    rank = {name: k for k, name in enumerate(LAYERS)}
    return sorted(f"{m} ({_layer(m)}) -> {t} ({_layer(t)})" for m, targets in graph.items() for t in targets
                  if rank[_layer(t)] > rank[_layer(m)])


def test_every_module_is_in_a_layer_folder_and_no_import_points_up():
    """Types too: the statistics name no controller type even for a type checker (the
    advice reaches them through their own protocols, ``statistics.advising``)."""
    graph = _graph(types=True)
    assert {_layer(m) for m in graph} == set(LAYERS)
    assert sorted(p.name for p in PACKAGE.iterdir() if p.is_dir() and p.name != "__pycache__") == \
        sorted(LAYERS[1:]), "a folder of compgen that is no layer"
    up = _arrows_up(graph)
    assert not up, "\n".join(up)


def test_the_layer_test_sees_an_arrow_up():
    """The statistics importing the advice (what they did before) is named."""
    graph = _graph()
    graph["compgen.statistics.identify"] |= {"compgen.planning.advice"}
    assert _arrows_up(graph) == [
        "compgen.statistics.identify (statistics) -> compgen.planning.advice (planning)"]


def test_the_tests_mirror_the_package():
    """One test folder per layer of compgen (tests/base for the modules at its top) and
    tests/project for what holds the whole project (its layers, sizes, docs, schemas); the
    shared helpers in tests/conftest.py."""
    tests = ROOT / "tests"
    assert {p.parent.name for p in tests.glob("*/test_*.py")} == {*LAYERS, "project"}
    assert not list(tests.glob("test_*.py")) and not list(tests.glob("*/*/test_*.py")), \
        "a test file outside the layers' folders"
