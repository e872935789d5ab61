"""The import rules of docs/architecture.md: who may import whom, no import cycle between
modules or packages, and every module importable in a fresh interpreter."""

import ast
import functools
import importlib.util
import os
import re
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

PACKAGES = ("drivers", "model", "sim", "gonio", "calibration", "gonio_watch", "gonio_cli")

FORBIDDEN = {
    "drivers": {"model", "sim", "gonio", "calibration", "gonio_cli", "gonio_watch"},
    "model": set(PACKAGES) - {"model"},
    "sim": set(PACKAGES) - {"sim", "model"},
    "gonio": {"calibration", "gonio_cli", "gonio_watch"},
    "calibration": {"sim", "gonio_cli", "gonio_watch"},
    "gonio_watch": {"drivers", "gonio_cli"},
}


def imported_packages(path: Path) -> set[str]:
    """Top-level package names a source file imports."""
    tree = ast.parse(path.read_text(), filename=str(path))
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module.split(".")[0])
    return names


def module_name(path: Path) -> str:
    """Dotted module name of a source file (a package's __init__.py: the package)."""
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


MODULES = {module_name(path): path
           for package in PACKAGES for path in sorted((ROOT / package).rglob("*.py"))}


def _runtime_imports(tree: ast.Module, typing: bool = False
                     ) -> Iterator[ast.Import | ast.ImportFrom]:
    """Every import statement that may run, at module level or inside a function; those under
    `if TYPE_CHECKING:`, which never run, only with `typing`."""
    todo: list[ast.AST] = [tree]
    while todo:
        node = todo.pop()
        if isinstance(node, ast.Import | ast.ImportFrom):
            yield node
        elif (isinstance(node, ast.If) and isinstance(node.test, ast.Name)
              and node.test.id == "TYPE_CHECKING" and not typing):
            todo.extend(node.orelse)
        else:
            todo.extend(ast.iter_child_nodes(node))


def _project_module(name: str) -> str | None:
    """The project module `import name` loads last: name, or the package holding it."""
    while name and name not in MODULES:
        name = name.rpartition(".")[0]
    return name or None


@functools.cache
def imported_modules(module: str, typing: bool = False) -> frozenset[str]:
    """Project modules that `module`'s imports name (`from P import m` names P.m if that is a
    module, else P)."""
    path = MODULES[module]
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    found = set()
    for node in _runtime_imports(ast.parse(path.read_text(), filename=str(path)), typing):
        if isinstance(node, ast.Import):
            found.update(_project_module(alias.name) for alias in node.names)
            continue
        base = node.module or ""
        if node.level:
            up = package.split(".")[:len(package.split(".")) - node.level + 1]
            base = ".".join(up + ([node.module] if node.module else []))
        for alias in node.names:
            sub = f"{base}.{alias.name}"
            found.add(sub if sub in MODULES else _project_module(base))
    return frozenset(found - {None, module})


def _packages_of(module: str) -> set[str]:
    parts = module.split(".")
    return {".".join(parts[:k]) for k in range(1, len(parts))}


def module_graph(typing: bool = False) -> dict[str, set[str]]:
    """module -> the modules its imports run: each imported module, and the packages around
    it that the importer is not inside (their __init__ runs first)."""
    graph = {}
    for module in MODULES:
        runs = set()
        for target in imported_modules(module, typing):
            runs |= {target} | (_packages_of(target) - _packages_of(module))
        graph[module] = runs - {module}
    return graph


def sibling_graph(typing: bool = False) -> dict[str, set[str]]:
    """At every level of the package tree, which child (subpackage or module) of a package
    imports which other child of it; the top level's children are PACKAGES."""
    graph: dict[str, set[str]] = {}
    for module in MODULES:
        for target in imported_modules(module, typing):
            a, b = module.split("."), target.split(".")
            k = next(i for i in range(len(a) + 1) if i == len(a) or i == len(b) or a[i] != b[i])
            if k < len(a) and k < len(b):  # neither holds the other
                graph.setdefault(".".join(a[:k + 1]), set()).add(".".join(b[:k + 1]))
    return graph


def cycles(graph: dict[str, set[str]]) -> list[set[str]]:
    """The strongly connected components of more than one node (Tarjan's algorithm)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    found = []

    def visit(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        for nxt in graph.get(node, ()):
            if nxt not in index:
                visit(nxt)
                low[node] = min(low[node], low[nxt])
            elif nxt in stack:
                low[node] = min(low[node], index[nxt])
        if low[node] == index[node]:
            component = set()
            while node not in component:
                component.add(stack.pop())
            if len(component) > 1:
                found.append(component)

    for node in sorted(graph):
        if node not in index:
            visit(node)
    return found


def describe_cycle(graph: dict[str, set[str]], component: set[str]) -> str:
    """One closed path through a cycle, e.g. "a -> b -> a" (the shortest from its first node)."""
    start = min(component)
    paths = {start: [start]}
    todo = [start]
    while todo:
        node = todo.pop(0)
        for nxt in sorted(graph.get(node, set()) & component):
            if nxt == start:
                return " -> ".join([*paths[node], start])
            if nxt not in paths:
                paths[nxt] = [*paths[node], nxt]
                todo.append(nxt)
    raise AssertionError(f"{sorted(component)} is not a cycle")


@pytest.mark.parametrize("package", sorted(FORBIDDEN))
def test_package_does_not_import_forbidden(package):
    offenders = {
        str(path.relative_to(ROOT)): sorted(imported_packages(path) & FORBIDDEN[package])
        for path in (ROOT / package).rglob("*.py")
    }
    assert {k: v for k, v in offenders.items() if v} == {}


def test_gonio_imports_sim_only_where_documented():
    # --sim and `gonio emulate` go through gonio/simulate.py; `gonio sweep` hands its work to
    # sim.sweep; the command line hands the emulator's truth to calibration
    # (gonio_cli/emulator_truth.py; docs/architecture.md).
    allowed = {"gonio/simulate.py", "gonio_cli/commands/sweep.py", "gonio_cli/emulator_truth.py"}
    users = {
        str(path.relative_to(ROOT))
        for package in ("gonio", "gonio_cli")
        for path in (ROOT / package).rglob("*.py")
        if "sim" in imported_packages(path)
    }
    assert users <= allowed


def test_gonio_reaches_a_devices_driver_only_through_its_kind():
    # a kind names its driver class as "module:Class" (gonio.device_kinds), loaded when a
    # device opens; the rest of gonio asks what a driver offers through drivers.base's
    # protocols (a sensor head's range: HeadRange), never by importing a device's module
    kinds = (ROOT / "gonio" / "device_kinds" / "__init__.py").read_text()
    drivers = set(re.findall(r'(?:serial_device|modbus_unit)\("(drivers\.\w+):', kinds))
    assert {"drivers.pm100", "drivers.esp", "drivers.zaber"} <= drivers
    importers = {module: sorted(imported_modules(module) & drivers) for module in MODULES
                 if module.split(".")[0] in ("gonio", "gonio_cli")
                 and imported_modules(module) & drivers}
    assert importers == {}


def test_the_cli_reaches_the_live_view_only_through_its_verb():
    # gonio_watch sits above gonio and calibration, below the CLI; `gonio watch` (and `gonio
    # scan --watch`, which starts it in a process of its own) is the one way in.
    users = {
        str(path.relative_to(ROOT))
        for path in (ROOT / "gonio_cli").rglob("*.py")
        if "gonio_watch" in imported_packages(path)
    }
    assert users <= {"gonio_cli/commands/watch.py"}


def test_only_the_record_hands_a_runs_sim_table_to_reduction():
    # The emulator's truth ([sim]) reaches reduction, fits, plots and exports only through
    # gonio.record.emulator_config, which withholds it from any run with a real device;
    # configs, the runner and --sim read it to build or describe the emulators.
    allowed = {"gonio/record.py", "gonio/config.py", "gonio/simulate.py", "gonio/runner.py"}
    reads = re.compile(r"""(config|raw)\s*(\.get\(\s*|\[\s*)["']sim["']""")
    readers = {
        str(path.relative_to(ROOT))
        for package in ("gonio", "gonio_cli", "calibration", "gonio_watch")
        for path in (ROOT / package).rglob("*.py")
        if reads.search(path.read_text())
    }
    assert readers <= allowed


BLUESKY = {"bluesky", "ophyd_async", "event_model"}  # the `bluesky` extra


def test_bluesky_is_reached_through_gonio_bluesky_and_one_export_only():
    # gonio.bluesky (the ophyd-async devices and the schedule plan) is an optional integration
    # that users import; nothing in the project imports it, so the base install never needs
    # the extra. The bluesky export needs event-model only.
    users = {
        str(path.relative_to(ROOT)): sorted(imported_packages(path) & BLUESKY)
        for package in PACKAGES for path in (ROOT / package).rglob("*.py")
        if imported_packages(path) & BLUESKY
    }
    allowed = {"calibration/exports/bluesky.py": ["event_model"]}
    assert {k: v for k, v in users.items()
            if not k.startswith("gonio/bluesky/") and allowed.get(k) != v} == {}
    importers = {module for module in MODULES if not module.startswith("gonio.bluesky")
                 and any(m.startswith("gonio.bluesky") for m in imported_modules(module))}
    assert importers == set()


@pytest.mark.parametrize("typing", [False, True], ids=["run", "typing"])
@pytest.mark.parametrize("graph", [module_graph, sibling_graph], ids=["modules", "packages"])
def test_no_import_cycle(graph, typing):
    """No module imports itself through others, lazy imports included; at every level of the
    package tree no subpackage or module imports itself through its siblings. Nor with the
    `TYPE_CHECKING` imports counted: a type that a module needs from one that imports it lives
    in the wrong module."""
    edges = graph(typing)
    found = [f"{describe_cycle(edges, c)} (one cycle of {', '.join(sorted(c))})"
             for c in cycles(edges)]
    assert not found, "import cycles:\n" + "\n".join(found)


def test_the_cycle_finder_names_a_cycle():
    edges = {"a": {"b"}, "b": {"c"}, "c": {"a", "d"}, "d": set(), "e": {"e"}}
    assert [describe_cycle(edges, c) for c in cycles(edges)] == ["a -> b -> c -> a"]


def test_the_graphs_see_lazy_and_package_imports():
    # gonio_cli's verbs import calibration inside their functions; importing gonio.store from
    # calibration runs gonio/__init__.py first; TYPE_CHECKING imports never run.
    modules = module_graph()
    assert "calibration.plot" in modules["gonio_cli.commands.plot"]
    assert {"gonio.store", "gonio"} <= modules["calibration.exports.run_files"]
    assert "calibration.reduce" not in modules["calibration.signature"]
    assert {"calibration", "gonio"} <= sibling_graph()["gonio_cli"]


@pytest.mark.parametrize("package", PACKAGES)
def test_every_module_imports_in_a_fresh_process(package):
    # One interpreter per top-level package (numpy and scipy cost a second or more each time),
    # importing each of its modules in turn; __main__ modules run a program, so not those.
    # gonio.bluesky needs the `bluesky` extra's ophyd-async.
    optional = () if importlib.util.find_spec("ophyd_async") else ("gonio.bluesky",)
    names = sorted(m for m, p in MODULES.items()
                   if m.split(".")[0] == package and p.name != "__main__.py"
                   and not m.startswith(optional))
    code = "import importlib, sys\nfor name in sys.argv[1:]:\n    importlib.import_module(name)\n"
    proc = subprocess.run([sys.executable, "-c", code, *names], cwd=ROOT, capture_output=True,
                          text=True, timeout=120, env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert proc.returncode == 0, proc.stderr[-3000:]
