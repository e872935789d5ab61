"""Fits on ReducedData drawn from the model: Walter's three samples, stiff cases, bad input."""

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from calibration.fit import FitError, FitOptions, fit
from calibration.synthetic import synthesize

WALTER = [("beckmann", 0.023), ("ggx", 0.394), ("ggx", 0.553)]


@pytest.mark.parametrize("distribution,alpha", WALTER)
def test_normal_incidence_fit_recovers_walter_samples(distribution, alpha):
    data = synthesize(distribution, alpha, eta=1.51, seed=11)
    result = fit(data)
    value, sigma = result.param("alpha")
    assert result.distribution == distribution
    assert abs(value - alpha) < 3.0 * sigma
    assert abs(value / alpha - 1.0) < 0.03
    assert 0.6 < result.chi2_dof_fit < 1.5
    # The model fitted at normal incidence predicts 30, 60 and 75 degrees.
    assert result.n_heldout > 2 * result.n_fit
    assert 0.8 < result.chi2_dof_heldout < 1.25
    others = [c for c in result.candidates if c["distribution"] != distribution]
    if distribution == "ggx":
        assert result.clearly_preferred and result.preferred_by > 100.0
    else:  # Phong is Walter's approximation of Beckmann: only GGX must be clearly rejected
        ggx = next(c for c in others if c["distribution"] == "ggx")
        assert ggx["chi2_dof_fit"] > 10.0


def test_reported_uncertainty_matches_scatter_of_repeated_fits():
    pulls = []
    for seed in range(30):
        data = synthesize("ggx", 0.394, seed=100 + seed, n_uniform=24, n_peak=8,
                          incidences_deg=(0.0,))
        value, sigma = fit(data, FitOptions(distributions=("ggx",))).param("alpha")
        pulls.append((value - 0.394) / sigma)
    pulls = np.array(pulls)
    assert abs(pulls.mean()) < 0.6  # 3 sigma of the mean of 30 unit-variance pulls
    assert 0.65 < pulls.std(ddof=1) < 1.4


def test_saturated_and_dark_points_masked():
    data = synthesize("beckmann", 0.023, seed=3)
    f = data.bsdf.copy()
    saturated = f > 0.2 * f.max()
    dark = f < 1e-5 * f.max()
    data.bsdf[saturated] = 0.2 * f.max()  # clipped readings
    data.bsdf[dark] = 0.0  # below the detector's floor
    data.valid[saturated | dark] = False
    assert saturated.sum() >= 3 and dark.sum() >= 10
    result = fit(data)
    value, sigma = result.param("alpha")
    assert result.distribution == "beckmann"
    assert abs(value - 0.023) < 3.0 * sigma and abs(value / 0.023 - 1) < 0.03
    assert result.n_fit == int((~(saturated | dark) & (data.theta_i_deg < 0.5)).sum())


def test_grazing_incidence_fit_with_eta_and_scale():
    data = synthesize("ggx", 0.394, seed=5, incidences_deg=(75.0, 85.0))
    data.bsdf *= 0.9
    data.sigma *= 0.9
    options = FitOptions(distributions=("ggx",), fit_eta=True, fit_scale=True,
                         fit_incidence_deg=None, eta=1.4)
    result = fit(data, options)
    for name, truth in (("alpha", 0.394), ("eta", 1.51), ("scale", 0.9)):
        value, sigma = result.param(name)
        assert abs(value - truth) < 3.0 * sigma, name
    assert result.n_heldout == 0 and result.chi2_dof_heldout is None


def test_correlated_masking_is_told_apart_when_offered():
    data = synthesize("ggx", 0.553, seed=8, masking="correlated", incidences_deg=(0.0, 60.0, 75.0))
    options = FitOptions(distributions=("ggx",), maskings=("separable", "correlated"),
                         fit_incidence_deg=None)
    assert fit(data, options).masking == "correlated"


def test_anisotropic_in_plane_fit_and_its_degeneracy_with_scale():
    # In the plane of incidence D depends on alpha_y only through its 1/(alpha_x alpha_y)
    # normalisation: both are fitted, but alpha_y cannot be told apart from a scale factor.
    data = synthesize("ggx", 0.394, seed=1, incidences_deg=(0.0,))
    result = fit(data, FitOptions(distributions=("ggx",), anisotropic=True))
    for name in ("alpha_x", "alpha_y"):
        value, sigma = result.param(name)
        assert abs(value - 0.394) < 3.0 * sigma
    default = fit(data, FitOptions(anisotropic=True))  # Phong is isotropic: reported, skipped
    assert default.distribution == "ggx"
    assert any("phong" in c.get("failed", "") for c in default.candidates)
    with pytest.raises(FitError, match="ill-conditioned.*alpha_y, scale"):
        fit(data, FitOptions(distributions=("ggx",), anisotropic=True, fit_scale=True))


def test_too_few_points_is_one_clear_error():
    data = synthesize("ggx", 0.394, seed=1, incidences_deg=(30.0,))
    with pytest.raises(FitError, match="usable points at incidence 0 deg"):
        fit(data)


def test_unknown_distribution_is_named():
    with pytest.raises(FitError, match="unknown distribution 'cauchy'"):
        FitOptions(distributions=("cauchy",))


def test_result_is_json_ready():
    result = fit(synthesize("ggx", 0.394, seed=2))
    text = json.dumps(result.to_dict())
    back = json.loads(text)
    assert back["distribution"] == "ggx"
    assert back["parameters"]["alpha"]["value"] == pytest.approx(result.alpha)
    assert back["parameters"]["eta"]["fixed"] is True
    assert back["n_fit"] == result.n_fit


def test_fit_overlay_figure_and_model_curve(tmp_path):
    from calibration.fitplot import model_curve, plot_fit

    data = synthesize("ggx", 0.394, seed=2, incidences_deg=(0.0, 60.0))
    result = fit(data)
    angle, curve = model_curve(result, 60.0, True, n=7)
    theta = np.radians(angle)
    wo = np.stack([np.sin(theta), 0 * theta, -np.cos(theta)], axis=1)
    wi = np.broadcast_to([-np.sin(np.pi / 3), 0.0, np.cos(np.pi / 3)], wo.shape)
    np.testing.assert_allclose(curve, result.model().eval(wi, wo))
    png = plot_fit(data, result, tmp_path / "fit.png", title="ground glass")
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 20_000


def test_narrow_lobe_through_a_finite_aperture():
    # Walter's anti-glare lobe (about 0.45 deg wide in transmission) seen through a 0.57 deg
    # half-angle aperture (10 mm at 500 mm): the fit must average its model over the aperture.
    data = synthesize("beckmann", 0.023, seed=9, incidences_deg=(0.0, 30.0),
                      aperture_half_angle_deg=0.573)
    result = fit(data, FitOptions(distributions=("beckmann", "ggx")))
    value, sigma = result.param("alpha")
    assert result.distribution == "beckmann" and result.optics.aperture_order >= 6
    assert abs(value - 0.023) < 3.0 * sigma and abs(value / 0.023 - 1) < 0.03
    assert result.chi2_dof_fit < 1.5 and result.chi2_dof_heldout < 1.5
    point_model = fit(data, FitOptions(distributions=("beckmann",), aperture_half_angle_deg=0.0))
    assert point_model.chi2_dof_fit > 5.0  # ignoring the aperture is visibly wrong


def test_smearing_matches_the_emulated_bench_power():
    # An independent route: sim.bench integrates f |cos o| over the aperture and the beam cone
    # to rtol 1e-6; dividing its power by what reduction divides by must give the smeared BSDF.
    from calibration.fit import build_model
    from calibration.smearing import Smearing
    from gonio.geometry import directions
    from sim.bench.config import build_bench

    bench = build_bench({
        "source": {"power_w": 1.0, "divergence_deg": 0.03},
        "sample": {"kind": "hemisphere", "distribution": "beckmann", "alpha": 0.023,
                   "eta": 1.51},
        "aperture": {"diameter_mm": 10.0, "distance_mm": 500.0, "rtol": 1e-6}})
    model = build_model("beckmann", 0.023, 1.51, "separable")
    omega = 4 * np.pi * np.sin(0.5 * np.arctan(0.01)) ** 2
    t_exit = 1 - ((1.51 - 1) / (1.51 + 1)) ** 2  # the hemisphere's exit face, normal incidence
    smearing = Smearing(np.degrees(np.arctan(0.01)), 12, 0.03, 6)
    for sample_deg, arm_deg in ((0.0, 179.6), (0.0, 180.3), (30.0, 190.1), (30.0, 191.3)):
        power = bench.power_w({"sample": sample_deg, "arm": arm_deg, "azimuth": 0.0,
                               "elevation": 0.0})
        wi, wo = directions(sample_deg, arm_deg)
        f = smearing.average(model, wi[None], wo[None])[0]
        assert power == pytest.approx(f * abs(wo[2]) * omega * t_exit, rel=5e-4)


@settings(max_examples=10, deadline=None, derandomize=True)
@given(alpha=st.floats(0.005, 1.2), distribution=st.sampled_from(["beckmann", "ggx"]),
       theta_i=st.sampled_from([0.0, 45.0, 80.0]), seed=st.integers(0, 1000))
def test_fit_converges_over_the_roughness_range(alpha, distribution, theta_i, seed):
    # From nearly specular to very rough, at normal, oblique and grazing incidence: the fit on
    # that incidence alone starts from the data's peak width and lands on the truth.
    data = synthesize(distribution, alpha, seed=seed, incidences_deg=(theta_i,), n_uniform=24,
                      n_peak=12)
    result = fit(data, FitOptions(distributions=(distribution,),
                                  fit_incidence_deg=(theta_i,)))
    value, sigma = result.param("alpha")
    assert abs(value - alpha) < 4.0 * sigma + 1e-3 * alpha
    assert result.chi2_dof_fit < 2.0
