"""The agents package's architecture, as lint: its rooms import only downward, nothing imports in
a cycle, no module uses another module's private names, and one module alone touches
Stable-Baselines3's private attributes.

The rooms, lowest first (a module may import from its own room and from the rooms below it):
``common`` < ``controllers`` < ``policies`` < ``evaluation`` < ``training`` < the commands
(``agents/<command>.py``). Deferred imports (inside a function, there to keep ``--help`` fast)
count as imports: a cycle or an upward import that only runs later is still one.

The rules read the source with :mod:`ast` and import nothing, so a violation is reported with its
file and line even where the code would not import."""

from __future__ import annotations

import ast
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

PACKAGE = "agents"
ROOT = Path(__file__).resolve().parents[2] / PACKAGE
#: The rooms, lowest first; a top-level module (a command) ranks above all of them.
ROOMS = ("common", "controllers", "policies", "evaluation", "training")
COMMANDS_RANK = len(ROOMS)
#: The one module that may read or write Stable-Baselines3's private attributes.
SB3_STATE_MODULE = f"{PACKAGE}.policies.sb3_state"


@dataclass(frozen=True)
class Import:
    """One import statement's target, as the module that holds it and (for ``from m import x``)
    the name taken from it."""

    source: str  #: the importing module (dotted)
    line: int
    module: str  #: the imported module (dotted, absolute)
    name: str | None  #: the name imported from ``module``, or None for ``import module``


def module_name(path: Path) -> str:
    relative = path.relative_to(ROOT.parent).with_suffix("")
    parts = relative.parts[:-1] if relative.name == "__init__" else relative.parts
    return ".".join(parts)


def modules() -> dict[str, Path]:
    return {module_name(path): path for path in sorted(ROOT.rglob("*.py"))}


def is_package(path: Path) -> bool:
    return path.name == "__init__.py"


def resolve(source: str, path: Path, level: int, module: str | None) -> str:
    """The absolute module of a (possibly relative) ``from`` import in ``source``."""
    if level == 0:
        return module or ""
    package = source.split(".") if is_package(path) else source.split(".")[:-1]
    base = package[: len(package) - (level - 1)]
    return ".".join(base + ([module] if module else []))


def imports_of(source: str, path: Path) -> Iterator[Import]:
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), filename=str(path))):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield Import(source, node.lineno, alias.name, None)
        elif isinstance(node, ast.ImportFrom):
            module = resolve(source, path, node.level, node.module)
            for alias in node.names:
                yield Import(source, node.lineno, module, alias.name)


def all_imports() -> list[Import]:
    return [found for source, path in modules().items() for found in imports_of(source, path)]


def target_module(found: Import, known: set[str]) -> str | None:
    """The module of the package that ``found`` depends on: ``from agents.x import y`` is module
    ``agents.x.y`` when that is a module (``from . import cli``), else ``agents.x``."""
    if found.name is not None and f"{found.module}.{found.name}" in known:
        return f"{found.module}.{found.name}"
    return found.module if found.module in known else None


def rank(module: str) -> int:
    parts = module.split(".")
    if len(parts) >= 2 and parts[1] in ROOMS:
        return ROOMS.index(parts[1])
    return COMMANDS_RANK


def where(found: Import) -> str:
    return f"{modules()[found.source].relative_to(ROOT.parent)}:{found.line}"


def test_the_rooms_exist_and_hold_modules() -> None:
    """The rules below would pass vacuously on a package that is not laid out in rooms."""
    found = modules()
    for room in ROOMS:
        assert f"{PACKAGE}.{room}" in found, f"agents/{room}/__init__.py is missing"
        assert any(name.startswith(f"{PACKAGE}.{room}.") for name in found), f"agents/{room}/ holds no module"


def test_no_module_imports_another_modules_private_names() -> None:
    """``from m import _name`` couples a module to what ``m`` keeps free to change. A name another
    module needs is public, with a docstring. (Within the agents package and from tether_gym.)"""
    offending = [
        f"{where(found)}: {found.source} imports {found.name} from {found.module}"
        for found in all_imports()
        if found.name is not None
        and found.name.startswith("_")
        and not found.name.startswith("__")
        and found.module.split(".")[0] in (PACKAGE, "tether_gym")
    ]
    assert not offending, "\n".join(offending)


def test_rooms_import_only_downward() -> None:
    known = set(modules())
    offending = []
    for found in all_imports():
        target = target_module(found, known)
        if target is not None and rank(target) > rank(found.source):
            offending.append(f"{where(found)}: {found.source} (room rank {rank(found.source)}) imports {target}")
    assert not offending, "rooms, lowest first: " + " < ".join((*ROOMS, "commands")) + "\n" + "\n".join(offending)


def strongly_connected(graph: dict[str, set[str]]) -> list[list[str]]:
    """Tarjan's algorithm: the strongly connected components of ``graph``."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    components: list[list[str]] = []

    def visit(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for successor in sorted(graph.get(node, ())):
            if successor not in index:
                visit(successor)
                low[node] = min(low[node], low[successor])
            elif successor in on_stack:
                low[node] = min(low[node], index[successor])
        if low[node] == index[node]:
            component = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                component.append(member)
                if member == node:
                    break
            components.append(sorted(component))

    for node in sorted(graph):
        if node not in index:
            visit(node)
    return components


def package_graph() -> dict[str, set[str]]:
    """Module -> the package modules it imports. A package's ``__init__`` that a submodule's
    import passes through is not an edge: importing ``agents.policies.format`` runs
    ``agents/policies/__init__.py`` first, but that is Python's order, not a dependency the code
    chose."""
    known = set(modules())
    graph: dict[str, set[str]] = {name: set() for name in known}
    for found in all_imports():
        target = target_module(found, known)
        if target is not None and target != found.source:
            graph[found.source].add(target)
    return graph


def test_no_import_cycles() -> None:
    cycles = [component for component in strongly_connected(package_graph()) if len(component) > 1]
    assert not cycles, "import cycles (each line a set of modules that import each other):\n" + "\n".join(
        " <-> ".join(cycle) for cycle in cycles
    )


def test_the_cycle_check_finds_a_cycle() -> None:
    """The rule can fail: a two-module and a three-module cycle are found, a chain is not."""
    graph = {"a": {"b"}, "b": {"a"}, "c": {"d"}, "d": {"e"}, "e": {"c"}, "f": {"g"}, "g": set()}
    assert sorted(c for c in strongly_connected(graph) if len(c) > 1) == [["a", "b"], ["c", "d", "e"]]


@pytest.mark.parametrize("module", sorted(modules()))
def test_only_the_sb3_state_module_touches_private_attributes(module: str) -> None:
    """SB3's private attributes (``model._n_updates``, ``policy._get_torch_save_params()``, ...)
    change between its releases without notice: one module reads and writes them, so that a new
    SB3 is adapted in one place. Any other module reads only its own objects' private attributes
    (through ``self`` or ``cls``)."""
    if module == SB3_STATE_MODULE:
        return
    path = modules()[module]
    tree = ast.parse(path.read_text(encoding="utf-8"))
    offending = [
        f"{path.relative_to(ROOT.parent)}:{node.lineno}: .{node.attr}"
        for node in ast.walk(tree)
        if isinstance(node, ast.Attribute)
        and node.attr.startswith("_")
        and not node.attr.startswith("__")
        and not (isinstance(node.value, ast.Name) and node.value.id in ("self", "cls"))
    ]
    assert not offending, "\n".join(offending)


def test_an_old_module_name_says_where_its_contents_went() -> None:
    """A module of the flat layout is refused with its new places, each of which exists; a name
    that never existed keeps Python's own error."""
    import importlib

    from agents import MOVED_MODULES

    found = modules()
    for old, places in MOVED_MODULES.items():
        assert f"{PACKAGE}.{old}" not in found, f"agents/{old}.py exists again: drop it from MOVED_MODULES"
        for module, _ in places:
            assert f"{PACKAGE}.{module}" in found, f"MOVED_MODULES names {module}, which does not exist"
        with pytest.raises(ModuleNotFoundError, match=f"agents.{old} is gone: .*{places[0][0]}"):
            importlib.import_module(f"{PACKAGE}.{old}")
    with pytest.raises(ModuleNotFoundError, match="No module named 'agents.never_was'"):
        importlib.import_module(f"{PACKAGE}.never_was")
