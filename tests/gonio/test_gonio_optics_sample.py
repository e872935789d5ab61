"""The experimenter's description of bench and sample: [optics] in the instrument config, [sample]
in the plan; one clear error per bad field, and the emulated bench built from them."""

import json
import tomllib
import warnings

import numpy as np
import pytest
from gonio_testkit import EXAMPLES, fast_config, gonio_cli, one_line_error, run_dir_of, write_toml

from gonio.config import parse_config
from gonio.errors import ConfigError, PlanError
from gonio.optics import optics_of_config
from gonio.plan import load_plan, parse_plan
from gonio.sample import KINDS, LIT_FROM, OPAQUE_KINDS
from model.optics.exit_face import OPAQUE_KINDS as OPTICS_OPAQUE_KINDS
from model.optics.exit_face import exit_view
from sim.bench import build_bench
from sim.bench.sample import KINDS as SIM_KINDS
from sim.bench.sample import LIT_FROM as SIM_LIT_FROM


def test_every_example_describes_its_bench_and_sample():
    for path in (EXAMPLES / "instruments").glob("*.toml"):
        cfg = parse_config(tomllib.loads(path.read_text()), path)
        assert cfg.optics is not None, path
        assert cfg.detector.wavelength_nm == cfg.optics.wavelength_nm
    for path in (EXAMPLES / "plans").glob("*.toml"):
        assert load_plan(path).sample is not None, path


def test_sample_kinds_name_the_benchs_kinds():
    assert KINDS == SIM_KINDS and LIT_FROM == SIM_LIT_FROM
    assert OPAQUE_KINDS == OPTICS_OPAQUE_KINDS


def test_receiver_solid_angle_from_the_aperture():
    optics = optics_of_config(fast_config())
    assert optics.aperture_half_angle_deg == pytest.approx(0.5729386976834859)
    assert optics.receiver_solid_angle_sr == pytest.approx(3.1413570537740097e-4)


@pytest.mark.parametrize("change, message", [
    ({"aperture_diameter_mm": 600.0}, "aperture_diameter_mm: 600 mm must be smaller"),
    ({"source_polarisation": "circular"}, "source_polarisation: must be \"unpolarised\", \"s\", "
                                          "\"p\" or a linear polariser's angle in degrees"),
    ({"wavelength_nm": "red"}, "wavelength_nm: must be a number"),
    ({"apperture_mm": 1.0}, "unknown key 'apperture_mm'"),
    ({"aperture_diameter_tolerance_mm": 10.0},
     r"aperture_diameter_tolerance_mm: \+-10 mm must be smaller than aperture_diameter_mm 10 mm"),
])
def test_bad_optics_is_one_error_naming_the_field(change, message):
    cfg = fast_config()
    cfg["optics"].update(change)
    with pytest.raises(ConfigError, match=message):
        parse_config(cfg)


def test_missing_optics_key_is_named_with_the_typo_that_hides_it():
    cfg = fast_config()
    del cfg["optics"]["bandwidth_nm"]
    with pytest.raises(ConfigError,
                       match=r"config: \[optics\]: missing required key 'bandwidth_nm'$"):
        parse_config(cfg)
    cfg["optics"]["bandwith_nm"] = 0.002
    with pytest.raises(ConfigError, match="'bandwidth_nm' \\(is 'bandwith_nm' a typo for it"):
        parse_config(cfg)


def test_detector_wavelength_must_agree_with_the_source():
    cfg = fast_config()
    cfg["detector"]["wavelength_nm"] = 532.0
    with pytest.raises(ConfigError,
                       match=r"config: \[detector\] wavelength_nm: 532 nm differs from"):
        parse_config(cfg)


PLAN = {"name": "p", "grid": [{"theta_i_deg": 0.0, "theta_o_deg": 20.0}]}


@pytest.mark.parametrize("sample, message", [
    ({"kind": "hemisphere", "eta": 1.5}, "missing required key 'id'"),
    ({"id": "a", "kind": "prism", "eta": 1.5}, "plan: \\[sample\\] kind: must be one of"),
    ({"id": "a", "kind": "slab", "eta": 1.5, "lit_from": "hemisphere"}, "needs kind"),
    ({"id": "a", "kind": "slab", "eta": 1.5, "k": 2.0}, "applies to kind = \"conductor\""),
    ({"id": "a", "kind": "slab", "eta": 1e-9}, "plan: \\[sample\\] eta: must be in"),
    ({"id": "a", "kind": "slab", "eta": 1.5, "reference": "mirror"},
     "plan: \\[sample\\] reference: must be one of angles, detector; got 'mirror'"),
    ({"id": "a", "kind": "coated"}, "plan: \\[sample\\]: missing required key 'eta'"),
    ({"id": "a", "kind": "diffuse", "eta": 0.0}, "plan: \\[sample\\] eta: must be in"),
    ({"id": "a", "kind": "reference", "lit_from": "hemisphere"}, "needs kind"),
    ({"id": "a", "kind": "diffuse", "k": 1.0}, "applies to kind = \"conductor\""),
])
def test_bad_sample_is_one_error_naming_the_field(sample, message):
    with pytest.raises(PlanError, match=message):
        parse_plan({**PLAN, "sample": sample})


@pytest.mark.parametrize("kind", ["diffuse", "reference"])
def test_a_diffuse_or_reference_panel_states_no_index_and_reflects_only(kind):
    sample = parse_plan({**PLAN, "sample": {"id": "panel", "kind": kind}}).sample
    assert sample.kind == kind and sample.eta is None
    assert parse_plan({**PLAN, "sample": {"id": "p", "kind": kind, "eta": 1.4}}).sample.eta == 1.4
    # reduction's exit view: reflection alone, factor 1, whatever the index
    wi = np.array([[0.0, 0.0, 1.0]] * 3)
    wo = np.array([[0.6, 0.0, 0.8], [0.6, 0.0, -0.8], [1.0, 0.0, 0.0]])
    w_eval, factor = exit_view(sample, wi, wo)
    assert factor.tolist() == [1.0, 0.0, 0.0] and np.array_equal(w_eval, wo)


def test_a_coated_sample_states_its_coat_index():
    sample = parse_plan({**PLAN, "sample": {"id": "paint", "kind": "coated", "eta": 1.5}}).sample
    assert (sample.kind, sample.eta) == ("coated", 1.5)


def test_the_emulated_bench_takes_its_geometry_from_the_description():
    cfg = fast_config("sim-walter-antiglare")
    bench = build_bench(cfg["sim"], cfg["optics"], {"kind": "slab", "eta": 1.7})
    assert (bench.aperture_diameter_mm, bench.distance_mm) == (3.0, 500.0)
    assert bench.sample.spec.kind == "slab" and bench.sample.spec.eta == 1.7
    assert bench.source.divergence_deg == 0.03
    # what [sim] states itself is the emulator's business and wins
    own = build_bench({**cfg["sim"], "aperture": {"diameter_mm": 4.0}}, cfg["optics"],
                      {"kind": "slab", "eta": 1.7})
    assert own.aperture_diameter_mm == 4.0


def test_a_polarised_bench_is_recorded_and_the_emulator_says_it_does_not_model_it():
    optics = {**fast_config()["optics"], "source_polarisation": "s"}
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        build_bench({}, optics)
    assert any("models unpolarised light only" in str(w.message) for w in caught)


def test_scan_records_optics_and_sample_and_takes_sample_id(tmp_path):
    cfg = write_toml(tmp_path / "cfg.toml", fast_config())
    plan = tomllib.loads((EXAMPLES / "plans" / "demo.toml").read_text())
    plan.update(instrument=str(cfg), grid=[{"theta_i_deg": 0.0, "theta_o_deg": 30.0}])
    plan_path = write_toml(tmp_path / "plan.toml", plan)
    done = gonio_cli("scan", plan_path, "--sim", "--out", tmp_path / "runs", "--no-plot",
                     "--sample-id", "GG-0042")
    assert done.returncode == 0, done.stderr
    run = run_dir_of(done)
    meta = json.loads((run / "meta.json").read_text())
    assert meta["sample"]["id"] == "GG-0042" and meta["sample"]["eta"] == 1.51
    assert meta["optics"]["receiver_solid_angle_sr"] == pytest.approx(3.1413570537740097e-4)
    assert json.loads((run / "plan.json").read_text())["sample"]["id"] == "GG-0042"
    del plan["sample"]
    bare = write_toml(tmp_path / "bare.toml", plan)
    warned = gonio_cli("scan", bare, "--sim", "--out", tmp_path / "runs", "--no-plot")
    assert warned.returncode == 0, warned.stderr  # it scans, and says before it moves why
    assert "has no [sample] table (id, kind, eta): the run will not reduce" in warned.stderr
    refused = gonio_cli("scan", bare, "--sim", "--sample-id", "x", "--out", tmp_path / "runs")
    assert refused.returncode != 0
    assert "needs a [sample] table" in one_line_error(refused.stderr)


def test_plan_summary_says_what_the_record_will_hold():
    done = gonio_cli("plan", EXAMPLES / "plans" / "walter-antiglare.toml")
    assert done.returncode == 0, done.stderr
    assert "sample: 'walter-antiglare', hemisphere, eta 1.51, lit from air" in done.stdout
    assert "receiver 3 mm at 500 mm = 2.827e-05 sr" in done.stdout
