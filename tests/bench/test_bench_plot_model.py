"""The plotted truth of an emulated run is the bench's own BSDF, labelled "emulator truth": with
multiple scattering on (by "auto" for rough glass) the curve carries orders >= 2, which the plain
microfacet model lacks in the lobe's wings. A real run has no truth curve."""

import numpy as np

from calibration.plot import emulated_truth, truth_curves
from model.bsdf import RoughDielectric
from model.optics.directions import in_plane_directions
from sim.bench import build_bench

SIM = {"source": {"divergence_deg": 0.0}, "sample": {"distribution": "ggx", "alpha": 0.394}}
OPTICS = {"wavelength_nm": 632.8, "aperture_diameter_mm": 10.0, "aperture_distance_mm": 500.0}
SAMPLE = {"id": "test", "kind": "hemisphere", "eta": 1.51}
META = {"sim": SIM, "optics": OPTICS, "sample": SAMPLE}


def test_emulated_runs_plot_the_benchs_bsdf_with_its_multiple_scattering():
    (label, (theta, f_bench)), = truth_curves(META, emulated_truth(META), 0.0, True).items()
    assert label == "emulator truth (ggx alpha 0.394 + multiple scattering)"
    wi, wo = in_plane_directions(0.0, theta, True)
    np.testing.assert_array_equal(f_bench, build_bench(SIM, OPTICS, SAMPLE).sample.bsdf(wi, wo))
    f_plain = RoughDielectric("ggx", 0.394, 1.51).eval(wi, wo)
    wing = np.abs(theta) > 60.0  # single scattering's transmitted lobe is all but gone there
    assert np.all(f_bench[wing] > f_plain[wing] + 1e-4)
    core = np.abs(theta) < 5.0
    np.testing.assert_allclose(f_bench[core], f_plain[core], rtol=0.02)


def test_the_truth_is_the_bench_the_run_described():
    """The emulated bench is built on the run's [sample]: a slab of eta 1.7 is what is drawn."""
    slab = {**META, "sample": {"id": "s", "kind": "slab", "eta": 1.7}}
    sample = emulated_truth(slab).bench_sample
    assert (sample.spec.kind, sample.spec.eta) == ("slab", 1.7)


def test_a_real_run_has_no_truth_curve():
    real = {"sim": None, "optics": OPTICS, "sample": SAMPLE, "aperture_half_angle_deg": 0.57}
    assert emulated_truth(real) is None
    assert truth_curves(real, None, 30.0, transmission=False) == {}
