"""The two CF checkers the suite reads NetCDF exports with, offline: the CF checker
(cfchecker, CF-1.8, with the tables in tests/fitting/cf_tables) and the IOOS compliance
checker's CF 1.8 suite at its strict criteria (which counts every finding, warnings too)."""

from __future__ import annotations

import json
from pathlib import Path

TABLES = Path(__file__).parent / "cf_tables"


def cf_counts(path: Path) -> dict:
    """The CF checker's error and warning counts for a file, offline."""
    from cfchecker.cfchecks import CFChecker

    checker = CFChecker(cfStandardNamesXML=str(TABLES / "cf-standard-name-table.xml"),
                        cfAreaTypesXML=str(TABLES / "area-type-table.xml"),
                        cfRegionNamesXML=str(TABLES / "standardized-region-list.xml"),
                        silent=True, version="1.8")
    results = checker.checker(str(path))
    said = [(name, r[c]) for name, r in [("global", results["global"]),
                                         *results["variables"].items()]
            for c in ("FATAL", "ERROR", "WARN") if r[c]]
    return {"counts": checker.get_total_counts(), "said": said}


def compliance_findings(path: Path, report: Path) -> list[str]:
    """What the IOOS compliance checker (cf:1.8, strict) says is wrong with a file: the
    messages of every check that did not score full marks ([] for a file that passes)."""
    from compliance_checker.runner import CheckSuite, ComplianceChecker

    CheckSuite.load_all_available_checkers()
    ComplianceChecker.run_checker(str(path), ["cf:1.8"], verbose=0, criteria="strict",
                                  output_filename=str(report), output_format="json")
    result = json.loads(report.read_text())["cf:1.8"]
    return [message for level in ("high_priorities", "medium_priorities", "low_priorities")
            for check in result[level] for message in check["msgs"]]
