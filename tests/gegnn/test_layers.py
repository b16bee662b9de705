"""The package's layering (docs/architecture.md): every import of a gegnn module, at the top of a file or
inside a function, goes to the same or a lower layer; no module imports itself back through others; the
layers stack at most MAX_FLOORS deep; no production file is longer than MAX_LINES.

Read from the source with ``ast``: nothing is imported. An import counts as written: ``from .x import y``
is an edge to ``x`` (to ``x.y`` where that is a module). The compiled ``gegnn._*`` modules import nothing
of the package and are left out; so is the package facade ``gegnn/__init__.py``, which nothing imports.
"""
import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PACKAGE = ROOT / "gegnn"

# Rooms (a sub-package, or a module beside them) and their layers; an import may go to its own room or to
# a room of a lower layer. docs/architecture.md has the same table with what each room holds.
LAYERS = {
    "config": 0, "metrics": 0, "threads": 0, "precision": 0, "graph": 0, "distributed": 0,
    "nn": 1, "fields": 1, "fitting": 1,
    "decoders": 2, "checkpoint": 2, "queries": 2, "finetune": 2,
    "model": 3,
    "training": 4, "pictures": 4,
    "cli": 5,
}
MAX_FLOORS = 6   # rooms on the longest chain of imports
MAX_LINES = 500  # lines of a production file (gegnn/, geodata/)
LONG_FILES: dict[str, str] = {}  # path -> why it may be longer; none at present


def _modules(package: Path = PACKAGE) -> dict[str, Path]:
    mods = {}
    for path in sorted(package.rglob("*.py")):
        parts = list(path.relative_to(ROOT).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        mods[".".join(parts)] = path
    return mods


MODULES = _modules()


def _imports(name: str, path: Path, modules: dict[str, Path] = MODULES) -> set[str]:
    """The modules of its package (``modules``) that ``name`` imports anywhere in its file."""
    package = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
    found = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[: len(package) - node.level + 1] + ([node.module] if node.module else [])
                module = ".".join(base)
            else:
                module = node.module or ""
            for alias in node.names:
                full = f"{module}.{alias.name}"
                found.add(full if full in modules else module)  # a module, or a name of one
        elif isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
    return {m for m in found if m in modules and m not in (package[0], name)}


GRAPH = {name: _imports(name, path) for name, path in MODULES.items()}
GEODATA = _modules(ROOT / "geodata")  # one room, its modules in a stack that imports only downward
GEODATA_GRAPH = {name: _imports(name, path, GEODATA) for name, path in GEODATA.items() if name != "geodata"}


def room(module: str) -> str:
    return module.split(".")[1]


def _cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """A cycle of ``graph`` (its nodes in order), or None."""
    state, stack = {}, []

    def visit(n):
        state[n] = "open"
        stack.append(n)
        for d in sorted(graph[n]):
            if state.get(d) == "open":
                return stack[stack.index(d):] + [d]
            if d not in state and (found := visit(d)):
                return found
        state[n] = "done"
        stack.pop()
        return None

    for n in sorted(graph):
        if n not in state and (found := visit(n)):
            return found
    return None


def _room_graph() -> dict[str, set[str]]:
    rooms = {room(m) for m in GRAPH if m != "gegnn"}
    graph = {r: set() for r in rooms}
    for m, deps in GRAPH.items():
        if m != "gegnn":
            graph[room(m)].update(room(d) for d in deps if room(d) != room(m))
    return graph


def test_every_module_has_a_layer():
    assert {room(m) for m in MODULES if m != "gegnn"} <= set(LAYERS), "new room: add it to LAYERS and docs"


def test_no_import_circle_between_modules():
    assert _cycle(GRAPH) is None, " -> ".join(_cycle(GRAPH))


def test_geodata_has_no_import_circle():
    """geodata's modules import each other only one way (its package facade aside), in functions too: the exact
    solver's memory check and the approximate solver imported each other's modules (0.3.3)."""
    assert _cycle(GEODATA_GRAPH) is None, " -> ".join(_cycle(GEODATA_GRAPH))


def test_no_import_circle_between_rooms():
    graph = _room_graph()
    assert _cycle(graph) is None, " -> ".join(_cycle(graph))


def test_imports_go_to_the_same_or_a_lower_layer():
    upward = [f"{m} -> {d}" for m, deps in sorted(GRAPH.items()) if m != "gegnn" for d in sorted(deps)
              if LAYERS[room(d)] > LAYERS[room(m)]]
    assert not upward


def test_subpackages_import_nothing_when_opened():
    """Opening a sub-package (what importing any of its modules does first) runs no import of another room:
    the model imports gegnn.queries.embedding without gegnn/queries/__init__.py pulling in anything else."""
    for name, path in MODULES.items():
        if path.name == "__init__.py" and name != "gegnn":
            assert all(room(d) == room(name) for d in GRAPH[name]), name


def test_a_subpackage_that_lists_its_modules_lists_them_all():
    """A sub-package's docstring that names its modules (``:mod:`~gegnn.fields.heat```) names every one: the
    fields' named the heat method's and not the virtual sources' on clouds, nor the close walls' sides."""
    for name, path in MODULES.items():
        doc = ast.get_docstring(ast.parse(path.read_text(encoding="utf-8"))) or ""
        if path.name != "__init__.py" or name == "gegnn" or f":mod:`~{name}." not in doc:
            continue
        own = [m for m in MODULES if m.startswith(name + ".") and m.count(".") == name.count(".") + 1]
        assert not [m for m in own if f"~{m}`" not in doc and f"~{m}." not in doc], name  # a module, or a name in it


def test_the_layers_stack_at_most_max_floors_deep():
    graph = _room_graph()
    floors = {}

    def floor(r):
        if r not in floors:
            floors[r] = 1 + max((floor(d) for d in graph[r]), default=0)
        return floors[r]

    deepest = max(graph, key=floor)
    assert floor(deepest) <= MAX_FLOORS, (deepest, floors)


@pytest.mark.parametrize("folder", ["gegnn", "geodata"])
def test_no_production_file_is_longer_than_max_lines(folder):
    long = {str(p.relative_to(ROOT)): n for p in sorted((ROOT / folder).rglob("*.py"))
            if (n := len(p.read_text(encoding="utf-8").splitlines())) > MAX_LINES}
    assert set(long) <= set(LONG_FILES), long


def test_the_checks_see_a_circle_and_an_upward_import():
    """The checks themselves: a hand-made circle is found, and the model importing the trainer is upward."""
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert _cycle({"a": {"b"}, "b": set()}) is None
    assert LAYERS[room("gegnn.training.loop")] > LAYERS[room("gegnn.model")]
    assert "gegnn.finetune" in GRAPH["gegnn.model"]  # GeGnn.finetune's import, inside the method, is seen
