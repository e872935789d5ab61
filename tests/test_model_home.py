"""model.bsdf is the BSDF's home; sim.bsdf re-exports its public names for one release, the same
objects, with a DeprecationWarning that names the new import. The emulator's truth reaches
calibration through the provider the composition root installs (tests/conftest.py, as
gonio_cli.main does), and a bad [sim] field is one calibration error naming it."""

import tomllib
from pathlib import Path

import pytest

import model.bsdf
from calibration.emulator_truth import truth_of
from calibration.reduce import optics_of
from calibration.values import CalibrationError
from sim.truth import EmulatorTruth

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("name", model.bsdf.__all__)
def test_sim_bsdf_gives_model_bsdfs_own_objects_with_a_warning(name):
    import sim.bsdf

    with pytest.warns(DeprecationWarning, match=f"import {name} from model.bsdf"):
        old_home = getattr(sim.bsdf, name)
    assert old_home is getattr(model.bsdf, name)


def test_sim_bsdf_names_what_it_lacks():
    import sim.bsdf

    with pytest.raises(AttributeError, match="'sim.bsdf' has no attribute 'Walker'"):
        sim.bsdf.Walker  # noqa: B018


def test_the_installed_truth_is_the_emulators():
    truth = truth_of({"sample": {"distribution": "beckmann", "alpha": 0.2}}, None,
                     {"id": "s", "kind": "hemisphere", "eta": 1.5})
    assert isinstance(truth, EmulatorTruth)
    assert truth.sample == {"distribution": "beckmann", "alpha": 0.2, "eta": 1.5,
                            "masking": "separable"}
    assert truth_of(None) is None and truth_of({}) is None  # not all emulated: no truth


def test_a_bad_sim_field_is_one_calibration_error_naming_it():
    with pytest.raises(CalibrationError, match=r"run config: \[sim.sample\] alpha"):
        truth_of({"sample": {"alpha": -1.0}})


def test_a_bad_sim_detector_field_is_one_calibration_error_naming_it():
    # the meter's table is read only when reduction asks the truth for its shot noise
    config = tomllib.loads((ROOT / "examples/instruments/sim-serial.toml").read_text())
    plan = tomllib.loads((ROOT / "examples/plans/demo.toml").read_text())
    config["detector"].pop("shot_noise_w", None)
    sim = {**config["sim"], "detector": {**config["sim"].get("detector", {}),
                                         "bandwidth_hz": -5}}
    with pytest.raises(CalibrationError, match=r"run config: \[sim.detector\] bandwidth_hz"):
        optics_of(config, plan=plan, sim=sim)
