"""Conformance: gonio's BiRD universal BRDF export checked by the BiRD project's own JSON schema
(v1.0, the unmodified snapshot in ../shared/third_party/bird-brdf-json-schema, or
$GONIO_THIRD_PARTY) with the jsonschema library, every format (uri, email, date-time) checked.
The demo plan scanned on the emulated serial bench, exported with `gonio export --format bird`,
validates with no error, every required field holding the plan's and config's values; the
schema refuses a file that breaks it (so the check is real); and `gonio reduce --import` of the
file gives back the export's points. A run recorded without [provenance], [environment], the
source's power and the sample's shape is refused by name, and exported with those given at
export time (`--provenance FILE.toml`) validates too, its provenance naming the file."""

from __future__ import annotations

import copy
import hashlib
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


@pytest.fixture(scope="module")
def bare_run(tmp_path_factory):
    """The demo plan scanned as a run recorded without [provenance], [environment], the
    source's power and the sample's shape and size (lab.toml leaves them to the lab): its
    directory."""
    from gonio.runner import new_scan

    folder = tmp_path_factory.mktemp("bird-bare")
    plan = tomllib.loads((EXAMPLES / "plans" / "demo.toml").read_text())
    for key in ("instrument", "environment"):
        plan.pop(key)
    for key in ("shape", "diameter_mm"):
        plan["sample"].pop(key)
    plan["averaging"] = 1
    cfg = fast_config("sim-serial")
    cfg.pop("provenance")
    for key in ("source_power_mw", "u_source_power_mw"):
        cfg["optics"].pop(key)
    result = new_scan(write_plan(folder, plan, cfg), sim=True, out=folder / "runs",
                      progress=False)
    assert result.outcome.status == "completed"
    return result.path


def test_a_run_without_them_is_refused_naming_the_keys(bare_run, tmp_path, capsys):
    out = tmp_path / "bare.json"
    assert main(["export", str(bare_run), "--format", "bird", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and not out.exists()
    assert ("config [provenance] lab, contact, email, street, building, postal_code, city, "
            "country, licence; config [optics] source_power_mw; plan [sample] shape, "
            "diameter_mm (or length_mm and width_mm); plan [environment] temperature_c (or a "
            "config environment sensor); --provenance FILE.toml gives them at export "
            "time") in err


def test_given_at_export_time_the_file_validates_and_names_them(bare_run, tmp_path):
    """tests/fitting/bird_given.toml gives what the run lacks (and repeats the source's name
    and type and the azimuth reference, which the run recorded alike)."""
    given = TESTS / "fitting" / "bird_given.toml"
    out = tmp_path / "bare.json"
    assert main(["export", str(bare_run), "--format", "bird", "--provenance", str(given),
                 "--out", str(out)]) == 0
    document = json.loads(out.read_text())
    errors = [f"{'/'.join(map(str, e.absolute_path))}: {e.message}"
              for e in bird_validator().iter_errors(document)]
    assert errors == []
    meta = document["metadata"]
    assert meta["provenance"]["organization"] == "Optics lab, Example University"
    assert meta["license"]["link"] == "https://creativecommons.org/licenses/by/4.0/"
    assert meta["environment"]["temperature"]["value"] == 22.1
    power = meta["instrumentation"]["illumination_system"]["source"]["power"]
    assert (power["value"], power["uncertainty"]) == (0.95, 0.01)
    assert meta["sample"]["shape"] == "disc"
    digest = hashlib.sha256(given.read_bytes()).hexdigest()
    said = meta["provenance"]["comments"]
    assert said.startswith("Given at export time (gonio export --provenance), not recorded by "
                           f"the run: the file {given.resolve()} (sha256 {digest}) gave "
                           "[provenance] lab, ")
    assert ("[environment] temperature_c, [environment] u_temperature_c, [optics] "
            "source_power_mw, [optics] u_source_power_mw, [sample] shape, [sample] "
            "diameter_mm, which the run had not recorded.") in said
    assert meta["comments"].endswith(said)
    record = meta["adhoc_section"]["gonio_record"]
    assert record["export_supplement"]["sha256"] == digest
    assert record["environment"]["temperature_c"] == 22.1
