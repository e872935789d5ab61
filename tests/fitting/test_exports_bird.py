"""The BiRD universal BRDF export and import (calibration.exports.bird, bird_read): a file
written from reduced data reads back as the same points, values and uncertainties (budget,
shared errors, validity, flags, index, wavelength); a record without what the format requires
is refused in one line naming the plan or config keys; a bad BiRD file is one error line
(exit 2). The validation against the BiRD schema itself is the conformance suite's
(tests/conformance/test_conformance_bird.py)."""

from __future__ import annotations

import hashlib
import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from calibration.exports.bird import write_bird
from calibration.exports.bird_supplement import read_supplement, supplemented
from calibration.exports.measured import columns
from calibration.formats import format_to_read
from calibration.formats.file_format import ImportOptions
from calibration.imports import read_measured
from calibration.reduced import ReducedData
from calibration.synthetic import synthesize
from calibration.values import CalibrationError
from gonio.config import load_config
from gonio.plan.parse import load_plan
from gonio_cli.main import main

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


def example_record() -> dict:
    """The record of a run of the demo plan on the emulated serial bench (the keys the BiRD
    export reads), from the example files as the parsers read them."""
    cfg = load_config(EXAMPLES / "instruments" / "sim-serial.toml")
    plan = load_plan(EXAMPLES / "plans" / "demo.toml")
    optics = cfg.optics.to_json()
    return {
        "run": "20261207T120000Z-demo", "plan": plan.name, "instrument": cfg.name,
        "started_utc": "2026-12-07T12:00:00.000+00:00",
        "wavelength_nm": optics["wavelength_nm"], "bandwidth_nm": optics["bandwidth_nm"],
        "receiver_solid_angle_sr": optics["receiver_solid_angle_sr"],
        "aperture_diameter_mm": optics["aperture_diameter_mm"],
        "aperture_distance_mm": optics["aperture_distance_mm"],
        "beam_diameter_mm": optics["beam_diameter_mm"],
        "beam_divergence_half_angle_deg": optics["divergence_deg"],
        "source_polarisation": optics["source_polarisation"],
        "analyser_polarisation": optics["analyser_polarisation"],
        "light_source": {k: optics[k] for k in ("source_name", "source_type", "source_power_mw",
                                          "u_source_power_mw")},
        "detector": cfg.detector.device,
        "detector_spectral_range_nm": list(optics["detector_spectral_range_nm"]),
        "sample": plan.sample.to_json(), "environment": plan.environment.to_json(),
        "provenance": cfg.provenance.to_json(), "sessions": [],
    }


@pytest.fixture(scope="module")
def glass():
    """Synthetic ground glass, both sides, with a budget of two components, a shared error,
    an invalid point, flags and a negative value (noise around a dark level)."""
    data = synthesize("ggx", 0.394, incidences_deg=(0.0, 30.0), n_uniform=12, n_peak=6, seed=3)
    n = len(data.bsdf)
    data.meta["wavelength_nm"] = 632.8
    data.components = {"dark": 0.6 * data.sigma, "beam_normalisation": 0.8 * data.sigma}
    flags = np.full(n, "", dtype=object)
    flags[2], flags[5] = "signature", "retried,signature"
    valid = np.ones(n, bool)
    valid[4] = False
    bsdf = data.bsdf.copy()
    bsdf[7] = -abs(bsdf[7])
    return replace(data, bsdf=bsdf, valid=valid, flags=flags.astype(str),
                   shared_rel=np.full((n, 1), 0.01))


def test_a_bird_file_reads_back_as_the_same_points(glass, tmp_path):
    path, notes = write_bird(glass, tmp_path / "glass.json", example_record())
    assert format_to_read(path).name == "bird"
    back = read_measured(path)
    kept = ~glass.transmission & (glass.bsdf >= 0)
    expected = glass.subset(kept)
    assert len(back.bsdf) == int(kept.sum()) > 10
    assert notes == [f"bird: left out {int(glass.transmission.sum())} points on the "
                     "transmission side (BiRD holds a BRDF; the CSV, NetCDF, ASTM and Zemax "
                     "exports hold them).", "bird: left out 1 point below 0 (BiRD's BRDF is "
                     ">= 0)."]
    want, got = columns(expected), columns(back)
    for name in ("theta_i_deg", "theta_o_deg", "bsdf", "sigma", "u_dark",
                 "u_beam_normalisation"):
        np.testing.assert_allclose(got[name], want[name], rtol=1e-12, atol=1e-9, err_msg=name)
    np.testing.assert_allclose(np.cos(np.radians(got["phi_o_deg"] - want["phi_o_deg"])), 1.0)
    np.testing.assert_array_equal(back.shared_rel, expected.shared_rel)
    np.testing.assert_array_equal(back.valid, expected.valid)
    np.testing.assert_array_equal(back.flags, expected.flags)
    assert not back.transmission.any()
    assert back.meta["eta"] == glass.meta["eta"] and back.meta["wavelength_nm"] == 632.8
    assert back.meta["record"]["provenance"]["lab"] == "gonio emulated bench"


def test_the_metadata_carries_the_plan_and_config_values(glass, tmp_path):
    path, _ = write_bird(glass, tmp_path / "glass.json", example_record())
    meta = json.loads(path.read_text())["metadata"]
    assert meta["environment"]["temperature"] == {"value": 21.5, "unit": "°C",
                                                  "uncertainty": 0.3, "uncertainty_unit": "°C"}
    assert meta["environment"]["relative_humidity"]["value"] == pytest.approx(42.0)
    assert meta["sample"]["shape"] == "hemisphere"
    assert meta["sample"]["dimensions"]["diameter"] == {"value": 25.4, "unit": "mm"}
    source = meta["instrumentation"]["illumination_system"]["source"]
    assert source["power"] == {"value": 1.0, "unit": "mW", "uncertainty": 0.02,
                               "uncertainty_unit": "mW"}
    assert source["central_wl"] == {"value": 632.8, "unit": "nm"}
    assert meta["provenance"]["contact_person"] == "gonio maintainers"
    assert meta["license"]["type"] == "CC-BY-4.0"


def test_a_record_without_provenance_or_environment_is_refused_in_one_line(glass, tmp_path):
    record = example_record()
    record["provenance"] = None
    record["environment"] = None
    record["light_source"]["source_power_mw"] = None
    out = tmp_path / "glass.json"
    with pytest.raises(CalibrationError) as caught:
        write_bird(glass, out, record)
    message = str(caught.value)
    assert "\n" not in message and not out.exists()
    assert message == ("export: --format bird needs what the run's record lacks: config "
                       "[provenance] lab, contact, email, street, building, postal_code, city, "
                       "country, licence; config [optics] source_power_mw; plan [environment] "
                       "temperature_c (or a config environment sensor); --provenance FILE.toml "
                       "gives them at export time")


@pytest.mark.parametrize("text, said", [
    ("{not json", "not JSON"),
    ('{"metadata": {}}', "not a BiRD BRDF file: data: missing"),
    ('{"data": {"BRDF": {"values": [1.0, 2.0], "unit": "1/sr"}, "theta_i": {"values": [0, 0], '
     '"unit": "deg"}, "phi_i": {"values": [0, 0], "unit": "deg"}, "theta_r": {"values": '
     '[10], "unit": "deg"}, "phi_r": {"values": [0, 0], "unit": "deg"}}}',
     "data.theta_r.values: 1 values for 2 BRDF values"),
    ('{"data": {"BRDF": {"values": [1.0, "x"], "unit": "1/sr"}}}',
     "data.BRDF.values[1]: not a number: 'x'"),
    ('{"data": {"BRDF": {"values": [1.0], "unit": "1/sr"}, "theta_i": {"values": [0], '
     '"unit": "grad"}}}', "data.theta_i.unit: must be one of deg, °, rad, got 'grad'"),
])
def test_a_bad_bird_file_is_one_error_line(text, said, tmp_path, capsys):
    path = tmp_path / "bad.json"
    path.write_text(text)
    assert main(["fit", "--import", str(path), "--eta", "1.5", "--sigma-relative", "0.05"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and said in err and str(path) in err


def test_another_labs_file_takes_its_stated_uncertainty_and_the_given_index(tmp_path):
    path = tmp_path / "other.json"
    data = {"theta_i": {"values": [0.0, 0.5236], "unit": "rad"},
            "phi_i": {"values": [0.0, 0.0], "unit": "rad"},
            "theta_r": {"values": [10.0, 40.0], "unit": "deg"},
            "phi_r": {"values": [0.0, 180.0], "unit": "deg"},
            "BRDF": {"values": [0.5, 0.25], "unit": "1/sr",
                     "uncertainty": {"value": 2.0, "unit": "%"}}}
    path.write_text(json.dumps({"metadata": {}, "data": data}))
    back = read_measured(path, ImportOptions(eta=1.5))
    np.testing.assert_allclose(back.sigma, [0.01, 0.005])
    np.testing.assert_allclose(back.theta_i_deg, [0.0, 30.0], atol=1e-3)
    assert back.meta["eta"] == 1.5


def nominal_scan(rng: np.random.Generator) -> ReducedData:
    """The demo plan's in-plane reflection points (theta_i 0 and 30 deg, theta_o -80 to 80 in
    10 deg steps) with directions carrying float noise of about 1e-14, as a bench's rotations
    give them."""
    theta_i, theta_o = np.meshgrid([0.0, 30.0], np.arange(-80.0, 81.0, 10.0), indexing="ij")
    theta_i, theta_o = np.radians(theta_i.ravel()), np.radians(theta_o.ravel())
    wi = np.stack([-np.sin(theta_i), 0 * theta_i, np.cos(theta_i)], axis=1)
    wo = np.stack([np.sin(theta_o), 0 * theta_o, np.cos(theta_o)], axis=1)
    wi, wo = (w + 1e-14 * rng.standard_normal(w.shape) for w in (wi, wo))
    wi, wo = (w / np.linalg.norm(w, axis=1, keepdims=True) for w in (wi, wo))
    n = len(wi)
    return ReducedData(wi, wo, np.full(n, 0.1), np.full(n, 0.001), np.ones(n, bool),
                       np.zeros(n, bool), {"eta": 1.51, "wavelength_nm": 632.8})


def test_the_angles_are_one_value_per_nominal_angle_and_one_source_azimuth(tmp_path):
    path, _ = write_bird(nominal_scan(np.random.default_rng(1)), tmp_path / "demo.json",
                         example_record())
    data = json.loads(path.read_text())["data"]
    assert set(data["theta_i"]["values"]) == {0.0, 30.0}
    assert set(data["theta_r"]["values"]) == {float(t) for t in range(0, 81, 10)}
    assert set(data["phi_i"]["values"]) == {180.0}  # the source's, normal incidence too
    assert set(data["phi_r"]["values"]) == {0.0, 180.0}


def test_a_record_without_the_wavelength_is_refused_in_one_line(glass, tmp_path):
    record = example_record()
    record["wavelength_nm"] = None
    with pytest.raises(CalibrationError, match=r"^export: --format bird needs what the run's "
                                               r"record lacks: config \[optics\] "
                                               r"wavelength_nm; --provenance"):
        write_bird(glass, tmp_path / "glass.json", record)
    assert not (tmp_path / "glass.json").exists()


@pytest.mark.parametrize("variable, values, said", [
    ("wavelength_i", {"values": [450.0, 550.0, 450.0], "unit": "nm"},
     "2 wavelengths in data.wavelength_i (450, 550 nm)"),
    ("polarization_i", {"notation": "sp", "values": ["s", "p", "s"]},
     "2 polarisations in data.polarization_i (p, s)"),
])
def test_a_spectral_or_polarised_file_is_refused_naming_what_it_holds(variable, values, said,
                                                                       tmp_path, capsys):
    path = tmp_path / "spectral.json"
    data = {name: {"values": [0.0, 10.0, 20.0], "unit": "deg"} for name in
            ("theta_i", "phi_i", "theta_r", "phi_r")}
    data["BRDF"] = {"values": [0.5, 0.25, 0.1], "unit": "1/sr"}
    data[variable] = values
    path.write_text(json.dumps({"metadata": {}, "data": data}))
    assert main(["fit", "--import", str(path), "--eta", "1.5", "--sigma-relative", "0.05"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and said in err and str(path) in err


#: The export-time file of the tests here and of the conformance suite's.
SUPPLEMENT = (Path(__file__).parent / "bird_given.toml").read_text()
#: What a lab bench's run without [provenance], [environment], the source's power and the
#: sample's shape lacks (lab.toml leaves them to the lab), as the file above gives it.
GIVEN = ["[provenance] lab", "[provenance] contact", "[provenance] email",
         "[provenance] street", "[provenance] building", "[provenance] postal_code",
         "[provenance] city", "[provenance] country", "[provenance] licence",
         "[provenance] licence_url", "[environment] temperature_c",
         "[environment] u_temperature_c", "[optics] source_power_mw",
         "[optics] u_source_power_mw", "[sample] shape", "[sample] diameter_mm"]


def bare_record() -> dict:
    """The example record as a run recorded without [provenance], [environment], the source's
    power and the sample's shape and size (an older run, or lab.toml's bench)."""
    record = example_record()
    record["provenance"] = record["environment"] = None
    record["light_source"].update(source_power_mw=None, u_source_power_mw=None)
    record["sample"].update(shape="", diameter_mm=None)
    return record


def supplement_file(tmp_path: Path, text: str = SUPPLEMENT) -> Path:
    path = tmp_path / "given.toml"
    path.write_text(text)
    return path


def test_an_export_time_file_fills_what_the_run_lacks_and_is_named(glass, tmp_path):
    path = supplement_file(tmp_path)
    record = supplemented(bare_record(), read_supplement(path))
    out, _ = write_bird(glass, tmp_path / "glass.json", record)
    meta = json.loads(out.read_text())["metadata"]
    assert meta["provenance"]["organization"] == "Optics lab, Example University"
    assert meta["license"] == {"type": "CC-BY-4.0",
                               "rights_holder": "Optics lab, Example University",
                               "link": "https://creativecommons.org/licenses/by/4.0/"}
    assert meta["environment"] == {"temperature": {"value": 22.1, "unit": "°C",
                                                   "uncertainty": 0.2, "uncertainty_unit": "°C"}}
    source = meta["instrumentation"]["illumination_system"]["source"]
    assert source["power"] == {"value": 0.95, "unit": "mW", "uncertainty": 0.01,
                               "uncertainty_unit": "mW"}
    assert source["name"] == "HeNe laser, 1 mW"  # recorded: the file's equal one not "given"
    assert meta["sample"]["shape"] == "disc"
    assert meta["sample"]["dimensions"]["diameter"] == {"value": 50.8, "unit": "mm"}
    digest = hashlib.sha256(path.read_bytes()).hexdigest()
    said = meta["provenance"]["comments"]
    assert said == (f"Given at export time (gonio export --provenance), not recorded by the "
                    f"run: the file {path.resolve()} (sha256 {digest}) gave "
                    f"{', '.join(GIVEN)}, which the run had not recorded.")
    assert meta["comments"].endswith(said)
    given = meta["adhoc_section"]["gonio_record"]["export_supplement"]
    assert given == {"file": str(path.resolve()), "sha256": digest, "gave": GIVEN}


@pytest.mark.parametrize("change, said", [
    (("temperature_c = 22.1", "temperature_c = 22.1\nhumidity_rel = 0.4"), None),
    (('source_type = "HeNe laser"', 'source_type = "LED"'),
     "[optics] source_type: 'LED' contradicts the run's recorded 'HeNe laser'"),
    (("diameter_mm = 50.8", "diameter_mm = 50.8\nid = \"other\""),
     "[sample] id: cannot be given at export time, only shape, azimuth_reference, "
     "diameter_mm, length_mm, width_mm, thickness_mm (the run's plan holds the rest"),
    (("[optics]", "[optics]\nwavelength_nm = 633.0"), "[optics] wavelength_nm: cannot be given"),
    (("[environment]", "[sim]\nseed = 1\n[environment]"), "[sim] cannot be given at export time"),
    (('email = "a.person@example.org"', 'email = "nobody"'),
     "[provenance] email: must be an e-mail address, got 'nobody'"),
    (("temperature_c = 22.1", "temperature = 22.1"),
     "[environment]: missing required key 'temperature_c'"),
    (("[sample]", "[sample"), "not valid TOML"),
])
def test_a_file_that_contradicts_the_run_or_gives_what_it_cannot_is_one_error(
        change, said, glass, tmp_path):
    path = supplement_file(tmp_path, SUPPLEMENT.replace(*change))
    out = tmp_path / "glass.json"
    if said is None:  # the run's own value again, and a key it lacks: taken
        record = supplemented(bare_record(), read_supplement(path))
        assert record["environment"]["humidity_rel"] == 0.4
        return
    with pytest.raises(CalibrationError) as caught:
        write_bird(glass, out, supplemented(bare_record(), read_supplement(path)))
    message = str(caught.value)
    assert "\n" not in message and said in message and str(path) in message
    assert not out.exists()


def test_a_recorded_value_the_file_contradicts_is_named(glass, tmp_path):
    path = supplement_file(tmp_path, "[environment]\ntemperature_c = 25.0\n")
    with pytest.raises(CalibrationError, match=r"given\.toml: \[environment\] temperature_c: "
                                               r"25\.0 contradicts the run's recorded 21\.5; an "
                                               r"export-time file only fills what the run lacks"):
        supplemented(example_record(), read_supplement(path))


def test_a_file_that_fills_part_leaves_the_rest_refused_by_name(glass, tmp_path):
    path = supplement_file(tmp_path, "[environment]\ntemperature_c = 22.1\n")
    record = supplemented(bare_record(), read_supplement(path))
    with pytest.raises(CalibrationError, match=r"^export: --format bird needs what the run's "
                                               r"record lacks: config \[provenance\] lab, "):
        write_bird(glass, tmp_path / "glass.json", record)


def test_provenance_is_for_bird_only(tmp_path, capsys):
    path = supplement_file(tmp_path)
    assert main(["export", str(tmp_path / "no-run"), "--format", "csv", "--provenance",
                 str(path), "--out", str(tmp_path / "x.csv")]) == 2
    assert capsys.readouterr().err.strip() == (
        "gonio export: error: export: --provenance gives what a BiRD file needs; --format csv "
        "does not take it")
