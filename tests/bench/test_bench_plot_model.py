"""The plotted model of an emulated run is the bench's own BSDF: with multiple scattering on
(by "auto" for rough glass) the curve carries orders >= 2, which the plain microfacet model
lacks in the lobe's wings."""

import numpy as np

from calibration.plot import in_plane_directions, model_curves
from sim.bench import build_bench

SIM = {"source": {"wavelength_nm": 632.8, "divergence_deg": 0.0},
       "sample": {"kind": "hemisphere", "distribution": "ggx", "alpha": 0.394, "eta": 1.51}}
META = {"model": {"distribution": "ggx", "alpha": 0.394, "eta": 1.51, "masking": "separable"},
        "kind": "hemisphere"}


def test_emulated_runs_plot_the_benchs_bsdf_with_its_multiple_scattering():
    plain = model_curves(META, 0.0, transmission=True)
    bench = model_curves({**META, "sim": SIM}, 0.0, transmission=True)
    (plain_label, (theta, f_plain)), = plain.items()
    (bench_label, (theta_b, f_bench)), = bench.items()
    assert bench_label.endswith("+ multiple scattering)") and "+" not in plain_label
    wi, wo = in_plane_directions(0.0, theta_b, True)
    np.testing.assert_array_equal(f_bench, build_bench(SIM).sample.bsdf(wi, wo))
    wing = np.abs(theta) > 60.0  # single scattering's transmitted lobe is all but gone there
    assert np.all(f_bench[wing] > f_plain[wing] + 1e-4)
    core = np.abs(theta) < 5.0
    np.testing.assert_allclose(f_bench[core], f_plain[core], rtol=0.02)


def test_without_the_bench_the_plain_model_is_plotted():
    (label, (theta, f)), = model_curves(META, 30.0, transmission=False).items()
    assert label == "model (ggx alpha 0.394)" and np.all(np.isfinite(f)) and f.max() > 0
