"""Conformance: gonio's BiRD universal BRDF export checked by the BiRD project's own JSON schema
(v1.0, the unmodified snapshot in ../shared/third_party/bird-brdf-json-schema, or
$GONIO_THIRD_PARTY) with the jsonschema library, every format (uri, email, date-time) checked.
The demo plan scanned on the emulated serial bench, exported with `gonio export --format bird`,
validates with no error, every required field holding the plan's and config's values; the
schema refuses a file that breaks it (so the check is real); and `gonio reduce --import` of the
file gives back the export's points."""

from __future__ import annotations

import copy
import json
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest

TESTS = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(Path(__file__).parent), str(TESTS / "gonio"), str(TESTS)]

from bird_schema import bird_validator, schema_folder  # noqa: E402
from gonio_testkit import EXAMPLES, fast_config, write_plan  # noqa: E402
from required_tools import require_module  # noqa: E402

from calibration.imports import read_measured  # noqa: E402
from gonio_cli.main import main  # noqa: E402

pytestmark = [
    pytest.mark.conformance,
    pytest.mark.skipif(not schema_folder().is_dir(), reason=f"the BiRD schema snapshot is not at "
                       f"{schema_folder()} (set GONIO_THIRD_PARTY to the third_party folder)"),
]
require_module("jsonschema", "jsonschema validates the BiRD files (the test extra)")


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    """The demo plan scanned on the emulated serial bench (instant motion) and its BiRD export:
    (run directory, the file)."""
    from gonio.runner import new_scan

    folder = tmp_path_factory.mktemp("bird")
    plan = tomllib.loads((EXAMPLES / "plans" / "demo.toml").read_text())
    plan.pop("instrument")
    plan["averaging"] = 1
    result = new_scan(write_plan(folder, plan, fast_config("sim-serial")), sim=True,
                      out=folder / "runs", progress=False)
    assert result.outcome.status == "completed"
    out = folder / "demo.json"
    assert main(["export", str(result.path), "--format", "bird", "--out", str(out)]) == 0
    return result.path, out


def test_the_validator_checks_the_formats_the_schema_names():
    checked = bird_validator().format_checker.checkers
    assert {"uri", "email", "date-time"} <= set(checked)


def test_the_export_of_an_emulated_run_validates(exported):
    _, path = exported
    document = json.loads(path.read_text())
    errors = [f"{'/'.join(map(str, e.absolute_path))}: {e.message}"
              for e in bird_validator().iter_errors(document)]
    assert errors == []
    meta, data = document["metadata"], document["data"]
    assert meta["provenance"]["organization"] == "gonio emulated bench"
    assert meta["environment"]["temperature"]["value"] == 21.5
    assert meta["sample"]["name"] == "demo-ground-glass"
    assert meta["instrumentation"]["detection_system"]["sensors"][0]["name"] == "S121C"
    assert len(data["BRDF"]["values"]) == len(data["uBRDF"]["values"]) > 20
    assert {name for name in data["adhoc_variables"] if name.startswith("u_")}


@pytest.mark.parametrize("break_it", [
    lambda d: d["metadata"].pop("provenance"),
    lambda d: d["metadata"]["provenance"].update(email="not an address"),
    lambda d: d["data"]["BRDF"]["values"].__setitem__(0, -1.0),
    lambda d: d["data"]["theta_r"]["values"].__setitem__(0, 95.0),
])
def test_the_schema_refuses_a_file_that_breaks_it(exported, break_it):
    document = json.loads(exported[1].read_text())
    broken = copy.deepcopy(document)
    break_it(broken)
    assert list(bird_validator().iter_errors(broken))


def test_the_import_gives_back_the_exported_points(exported, tmp_path):
    _, path = exported
    document = json.loads(path.read_text())
    back = read_measured(path)
    np.testing.assert_allclose(back.bsdf, document["data"]["BRDF"]["values"], rtol=0)
    np.testing.assert_allclose(back.sigma, document["data"]["uBRDF"]["values"], rtol=0)
    np.testing.assert_allclose(back.theta_i_deg, document["data"]["theta_i"]["values"],
                               atol=1e-9)
    csv = tmp_path / "reduced.csv"
    assert main(["reduce", "--import", str(path), "--out", str(csv)]) == 0
