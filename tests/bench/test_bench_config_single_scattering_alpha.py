"""[sim.sample] single_scattering_alpha and single_scattering_alpha_u document the emulator's
truth (the alpha a single-scattering fit returns on a bench that scatters more than once) and
change nothing the bench does; bad values are one SimConfigError naming the key; the
emulator's truth and `gonio fit`'s summary carry them."""

import pytest

from gonio_cli.commands.fit import summary
from sim.bench.config import build_bench
from sim.devices.photodiode import SimConfigError
from sim.truth import EmulatorTruth

SAMPLE = {"distribution": "ggx", "alpha": 0.394, "multiple_scattering": False}
STATED = {"single_scattering_alpha": 0.4025, "single_scattering_alpha_u": 0.0035}
WHERE = {"sample": 20.0, "arm": 150.0}  # transmitted, 10 deg off the refracted peak


def test_the_informational_keys_change_nothing_the_bench_does():
    plain = build_bench({"sample": SAMPLE})
    stated = build_bench({"sample": {**SAMPLE, **STATED}})
    assert stated.sample.spec == plain.sample.spec
    assert stated.power_w(WHERE) == plain.power_w(WHERE) > 0.0


@pytest.mark.parametrize("extra, refused", [
    ({"single_scattering_alpha": 0.0}, r"\[sim.sample\] single_scattering_alpha: must be a "
                                       r"number >= 0.0001 and <= 4, got 0.0"),
    ({"single_scattering_alpha": "0.4"}, r"\[sim.sample\] single_scattering_alpha: must be"),
    ({**STATED, "single_scattering_alpha_u": -1e-3},
     r"\[sim.sample\] single_scattering_alpha_u: must be a number > 0, got -0.001"),
    ({"single_scattering_alpha_u": 0.0035},
     r"\[sim.sample\] single_scattering_alpha_u: needs single_scattering_alpha"),
])
def test_bad_values_are_one_error_naming_the_key(extra, refused):
    with pytest.raises(SimConfigError, match=refused):
        build_bench({"sample": {**SAMPLE, **extra}})


def test_the_truth_and_the_fit_summary_state_both_alphas():
    truth = EmulatorTruth({"sample": {**SAMPLE, **STATED}})
    assert truth.sample == {"distribution": "ggx", "alpha": 0.394, "eta": 1.51,
                            "masking": "separable", **STATED}
    assert "single_scattering_alpha" not in EmulatorTruth({"sample": SAMPLE}).sample
    out = {"run": "r", "distribution": "ggx", "masking": "separable",
           "parameters": {"alpha": {"value": 0.4025, "sigma": 0.0034}},
           "chi2_dof_fit": 3e5, "n_fit": 133, "chi2_dof_heldout": None, "candidates": [],
           "clearly_preferred": True, "emulator_truth": truth.sample}
    assert ("alpha 0.394 is the microsurface's, under multiple scattering; the default "
            "single-scattering fit (normal incidence) of this bench returns 0.4025 +- 0.0035"
            in summary(out))
