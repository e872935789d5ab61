"""Who measured and in what room: the config's [provenance], the plan's [environment], the
source and detector range in [optics] and the sample's shape and size in [sample]; one clear
error per bad field, every example states them, and the record of a run carries them."""

import tomllib

import pytest
from gonio_testkit import EXAMPLES, fast_config

from gonio.config import parse_config
from gonio.errors import ConfigError, PlanError
from gonio.plan import load_plan, parse_plan

PLAN = {"name": "p", "grid": [{"theta_i_deg": [0.0], "theta_o_deg": [20.0]}],
        "sample": {"id": "s", "kind": "slab", "eta": 1.5}}


def changed(table: str, change: dict) -> dict:
    """The example config with `change` made to one table (a key given None: removed)."""
    cfg = fast_config()
    cfg[table] = {k: v for k, v in {**cfg[table], **change}.items() if v is not None}
    return cfg


def test_every_example_states_the_source_and_sample_size_and_the_emulated_ones_who_and_where():
    """The emulated bench's configs and plans state their provenance and their room as the
    emulator's own (declared); the real bench's (lab.toml, and the plans run on it) leave both
    to the lab, so that no made-up lab or room reaches a file."""
    for path in (EXAMPLES / "instruments").glob("*.toml"):
        cfg = parse_config(tomllib.loads(path.read_text()), path)
        assert cfg.optics.source_power_mw > 0 and cfg.optics.detector_spectral_range_nm, path
        if path.name == "lab.toml":
            assert cfg.provenance is None
        else:
            assert cfg.provenance is not None and cfg.provenance.licence, path
            assert cfg.provenance.lab == "gonio emulated bench", path
    for path in (EXAMPLES / "plans").glob("*.toml"):
        plan = load_plan(path)
        assert plan.sample.shape and plan.sample.dimensions_mm == {"diameter": 25.4}, path
        if plan.instrument.name == "lab.toml":
            assert plan.environment is None, path
        else:
            assert plan.environment.temperature_c == 21.5, path
            assert plan.environment.notes.startswith("declared for the emulated room"), path


@pytest.mark.parametrize("change, message", [
    ({"email": "nobody"}, r"\[provenance\] email: must be an e-mail address, got 'nobody'"),
    ({"lab": " "}, r"\[provenance\] lab: must not be empty"),
    ({"licence": None}, r"\[provenance\]: missing required key 'licence'"),
    ({"labb": "x"}, r"\[provenance\]: unknown key 'labb'"),
])
def test_bad_provenance_is_one_error_naming_the_key(change, message):
    with pytest.raises(ConfigError, match=message):
        parse_config(changed("provenance", change))


def test_the_licence_holder_is_the_lab_unless_stated():
    cfg = parse_config(fast_config())
    assert cfg.provenance.licence_holder == cfg.provenance.lab


@pytest.mark.parametrize("change, message", [
    ({"source_power_mw": 0.0}, r"source_power_mw: must be in \(0, "),
    ({"u_source_power_mw": 0.1, "source_power_mw": None},
     "u_source_power_mw: needs source_power_mw"),
    ({"detector_spectral_range_nm": [1100.0, 400.0]}, "detector_spectral_range_nm: must have lo"),
    ({"detector_spectral_range_nm": [-5.0, 400.0]}, "must be wavelengths > 0 nm"),
])
def test_bad_source_or_detector_range_is_one_error(change, message):
    with pytest.raises(ConfigError, match=message):
        parse_config(changed("optics", change))


@pytest.mark.parametrize("table, message", [
    ({"temperature_c": "warm"}, r"\[environment\] temperature_c: must be a number"),
    ({"humidity_rel": 0.4}, r"\[environment\]: missing required key 'temperature_c'"),
    ({"temperature_c": 20.0, "humidity_rel": 42.0}, r"humidity_rel: must be in \[0, 1\]"),
    ({"temperature_c": 20.0, "u_humidity_rel": 0.02}, "u_humidity_rel: needs humidity_rel"),
])
def test_bad_environment_is_one_error(table, message):
    with pytest.raises(PlanError, match=message):
        parse_plan({**PLAN, "environment": table})


def test_bad_sample_size_is_one_error():
    with pytest.raises(PlanError, match=r"\[sample\] diameter_mm: must be in \(0, "):
        parse_plan({**PLAN, "sample": {**PLAN["sample"], "diameter_mm": -1.0}})
