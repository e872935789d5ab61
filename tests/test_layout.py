"""The import rules of docs/architecture.md: drivers and sim stay independent."""

import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

FORBIDDEN = {
    "drivers": {"sim", "gonio", "calibration", "gonio_watch"},
    "sim": {"drivers", "gonio", "calibration", "gonio_watch"},
    "calibration": {"gonio_watch"},
    "gonio_watch": {"drivers"},
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


@pytest.mark.parametrize("package", sorted(FORBIDDEN))
def test_package_does_not_import_forbidden(package):
    offenders = {
        str(path.relative_to(ROOT)): sorted(imported_packages(path) & FORBIDDEN[package])
        for path in (ROOT / package).rglob("*.py")
    }
    assert {k: v for k, v in offenders.items() if v} == {}


def test_gonio_imports_sim_only_where_documented():
    # --sim and `gonio emulate` go through gonio/simulate.py; the model-only verbs
    # (lut, sweep) hand their work to sim.lut (docs/architecture.md, departures).
    allowed = {"gonio/simulate.py", "gonio/commands/lut.py", "gonio/commands/sweep.py"}
    users = {
        str(path.relative_to(ROOT))
        for path in (ROOT / "gonio").rglob("*.py")
        if "sim" in imported_packages(path)
    }
    assert users <= allowed


def test_gonio_reaches_the_live_view_only_through_its_verb():
    # gonio_watch sits above gonio and calibration; `gonio watch` (and `gonio scan --watch`,
    # which starts it in a process of its own) is the one way in.
    users = {
        str(path.relative_to(ROOT))
        for path in (ROOT / "gonio").rglob("*.py")
        if "gonio_watch" in imported_packages(path)
    }
    assert users <= {"gonio/commands/watch.py"}


def test_only_the_record_hands_a_runs_sim_table_to_reduction():
    # The emulator's truth ([sim]) reaches reduction, fits, plots and exports only through
    # gonio.record.emulator_config, which withholds it from any run with a real device;
    # configs, the runner and --sim read it to build or describe the emulators.
    allowed = {"gonio/record.py", "gonio/config.py", "gonio/simulate.py", "gonio/runner.py"}
    reads = re.compile(r"""(config|raw)\s*(\.get\(\s*|\[\s*)["']sim["']""")
    readers = {
        str(path.relative_to(ROOT))
        for package in ("gonio", "calibration", "gonio_watch")
        for path in (ROOT / package).rglob("*.py")
        if reads.search(path.read_text())
    }
    assert readers <= allowed
