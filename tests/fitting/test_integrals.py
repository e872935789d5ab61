"""Integrated quantities (calibration.integrals): the cells' quadrature against closed forms,
a known model's integrals from noisy synthetic data within U against an independent quadrature,
and the terms' behaviour where the data are the model itself."""

from __future__ import annotations

import math

import numpy as np
import pytest

from calibration.exports.zemax import hemisphere_integral
from calibration.fit import build_model, fit
from calibration.hemisphere import cells
from calibration.integrals import (
    GLOSS_STANDARD_INDEX,
    black_glass_reflectance,
    block_cells,
    incidence,
    integrals,
    value_of,
)
from calibration.pipeline import DEFAULT_SLOPE_FIT, slope_fit_options
from calibration.synthetic import synthesize

ETA = 1.51


def test_cells_integrate_the_cosine_and_the_iso_cone_in_closed_form():
    grid = cells(0.0, "BRDF")  # about the normal: cos-weighted solid angle pi
    assert grid.weight.sum() == pytest.approx(math.pi, rel=1e-6)
    cone = grid.weight[:, (grid.radial_deg >= 2.0) & (grid.radial_deg <= 85.0)].sum()
    assert cone == pytest.approx(math.pi * (math.sin(math.radians(85)) ** 2
                                            - math.sin(math.radians(2)) ** 2), rel=1e-6)
    oblique = cells(60.0, "BRDF")  # about an oblique specular direction, cut by the horizon
    assert oblique.weight.sum() == pytest.approx(math.pi, rel=2e-3)


def test_black_glass_reflectance_is_fresnel_of_n_1567():
    n = GLOSS_STANDARD_INDEX
    assert black_glass_reflectance(0.0) == pytest.approx(((n - 1) / (n + 1)) ** 2, rel=1e-9)
    ci = 0.5  # 60 deg: Fresnel's s and p amplitudes by hand
    ct = math.sqrt(1 - (math.sin(math.radians(60.0)) / n) ** 2)
    rs, rp = (ci - n * ct) / (ci + n * ct), (n * ci - ct) / (n * ci + ct)
    assert black_glass_reflectance(60.0) == pytest.approx((rs ** 2 + rp ** 2) / 2, rel=1e-9)


@pytest.mark.parametrize("geometry, alpha", [(20.0, 0.001), (20.0, 0.003), (60.0, 0.001),
                                             (60.0, 0.003), (60.0, 0.005), (85.0, 0.002),
                                             (85.0, 0.003), (85.0, 0.005)])
def test_a_near_specular_black_glass_gives_100_gloss_units(geometry, alpha):
    """The gloss scale: a smooth black glass (n 1.567, the primary standard) reflects its
    Fresnel reflectance into the receptor window, 100 GU. The lobe must lie inside the window
    and be resolved by the cells: Beckmann's Gaussian slopes (GGX's tails, a fraction
    alpha^2 / 2 t^2 beyond a slope t, cut 3 % from the 20 deg window's +-0.9 deg at alpha
    0.002), alpha 0.003 or less (the slopes' sigma 0.0021 against the 20 deg window's
    half-width of 0.0079 in slope: 3.7 sigma) where the window is narrow; at 85 deg a lobe of
    alpha 0.002 about 0.2 deg long and flattened across the plane by cos 85 deg, which the
    cells' narrowest radial panels and azimuth panels near the plane resolve."""
    model = build_model("beckmann", alpha, GLOSS_STANDARD_INDEX, "separable")
    grid = block_cells(geometry, False, GLOSS_STANDARD_INDEX)
    f = np.zeros(grid.weight.shape)
    side = grid.weight > 0
    f[side] = model.eval(np.broadcast_to(incidence(geometry), (int(side.sum()), 3)),
                         grid.wo[side])
    assert value_of("gloss", grid, geometry, f) == pytest.approx(100.0, abs=1.0)
    assert value_of("reflectance", grid, geometry, f) == pytest.approx(
        black_glass_reflectance(geometry), rel=0.01)


def _model_integral(alpha: float, theta_i: float, transmission: bool, lo: float = 0.0,
                    hi: float = 180.0) -> float:
    """The GGX model's integral of f |cos o| between lo and hi deg from the specular or direct
    direction, by the Zemax export's quadrature (independent of calibration.hemisphere)."""
    model = build_model("ggx", alpha, ETA, "separable")
    wi = incidence(theta_i)
    angle = (math.degrees(math.asin(math.sin(math.radians(theta_i)) / ETA)) if transmission
             else theta_i)
    scatter_type = "BTDF" if transmission else "BRDF"
    sign = -1.0 if transmission else 1.0
    c = np.array([math.sin(math.radians(angle)), 0.0, sign * math.cos(math.radians(angle))])

    def f(wo: np.ndarray) -> np.ndarray:
        radial = np.degrees(np.arccos(np.clip(wo @ c, -1.0, 1.0)))
        inside = (radial >= lo) & (radial <= hi)
        return np.where(inside, model.eval(np.broadcast_to(wi, wo.shape), wo), 0.0)

    # the quadrature's panels split at twice the width: put a cone's inner edge on one
    return hemisphere_integral(f, scatter_type, angle, lo / 2 if lo > 0 else 2.0)


@pytest.mark.parametrize("seed", [1, 2])
def test_noisy_synthetic_integrals_lie_within_u_of_the_model(seed):
    alpha = 0.3
    data = synthesize("ggx", alpha, ETA, incidences_deg=(0.0, 60.0), relative_noise=0.01,
                      seed=seed, n_uniform=18, n_peak=8)
    found = {(i.theta_i_deg, i.name): i for i in integrals(
        data, fit(data, slope_fit_options(DEFAULT_SLOPE_FIT)))}
    for theta_i in (0.0, 60.0):
        truth = {
            "reflectance": _model_integral(alpha, theta_i, False),
            "tis_backward": _model_integral(alpha, theta_i, False, 2.0, 85.0),
            "transmittance": _model_integral(alpha, theta_i, True),
            "tis_forward": _model_integral(alpha, theta_i, True, 2.0, 85.0),
            "haze": _model_integral(alpha, theta_i, True, 2.5) / _model_integral(
                alpha, theta_i, True)}
        for name, value in truth.items():
            got = found[(theta_i, name)]
            assert abs(got.value - value) <= 2 * got.u, (theta_i, name, got, value)
            assert got.u < 0.05 * value
    assert (60.0, "gloss") in found and found[(60.0, "gloss")].value > 0


def test_data_equal_to_the_model_give_its_integrals_with_no_interpolation_term():
    alpha = 0.3
    data = synthesize("ggx", alpha, ETA, incidences_deg=(0.0,), relative_noise=1e-9,
                      dynamic_range=1e12, n_uniform=18, n_peak=8)
    found = {i.name: i for i in integrals(data, fit(data, slope_fit_options(DEFAULT_SLOPE_FIT)))}
    assert found["reflectance"].value == pytest.approx(_model_integral(alpha, 0.0, False),
                                                       rel=2e-3)
    assert found["transmittance"].value == pytest.approx(_model_integral(alpha, 0.0, True),
                                                         rel=2e-3)
    for name in ("reflectance", "transmittance"):
        assert found[name].components["interpolation"] < 1e-6 * found[name].value
        assert found[name].components["model_form"] < 1e-6 * found[name].value


def test_beyond_the_last_measured_angle_the_fill_follows_the_data_at_the_rows_ends():
    """A GGX lobe plus a Lambertian part (albedo 0.05) that the GGX fit misses, measured in
    plane to 75 deg at normal incidence: the cells past 75 deg take the model scaled as the
    data at the rows' ends scale it, so the reflectance is the lobe's plus the Lambertian's
    within U and 1 % (0.4 %), where the bare model there reads 3.7 % low."""
    alpha, albedo = 0.3, 0.05
    data = synthesize("ggx", alpha, ETA, incidences_deg=(0.0,), relative_noise=1e-4,
                      n_uniform=24, n_peak=8, sides=("reflection",), seed=3)
    data.bsdf = data.bsdf + albedo / math.pi
    data = data.subset(np.degrees(np.arccos(data.wo[:, 2])) <= 75.0)
    found = {i.name: i for i in integrals(data, fit(data, slope_fit_options(DEFAULT_SLOPE_FIT)))}
    grid = block_cells(0.0, False, ETA)
    f = np.zeros(grid.weight.shape)
    side = grid.on_side
    f[side] = build_model("ggx", alpha, ETA, "separable").eval(
        np.broadcast_to(incidence(0.0), (int(side.sum()), 3)), grid.wo[side]) + albedo / math.pi
    truth = value_of("reflectance", grid, 0.0, f)
    got = found["reflectance"]
    assert abs(got.value - truth) <= 2 * got.u, (got, truth)
    assert got.value == pytest.approx(truth, rel=0.01)


@pytest.mark.parametrize("alpha", [0.002, 0.003])
def test_a_black_glass_measured_in_plane_at_85_deg_reads_100_gloss_units_within_u(alpha):
    """Noisy in-plane data (1 %) of a black glass at ISO 2813's 85 deg geometry, reduced by
    the whole path (fit, interpolation, cells): 100 GU within U (about 0.7 GU; 3-deg azimuth
    cells read 106 and 105 GU)."""
    data = synthesize("beckmann", alpha, GLOSS_STANDARD_INDEX, incidences_deg=(85.0,),
                      relative_noise=0.01, n_uniform=24, n_peak=16, sides=("reflection",),
                      seed=1)
    found = {i.name: i for i in integrals(data, fit(data, slope_fit_options(DEFAULT_SLOPE_FIT)))}
    gloss = found["gloss"]
    assert abs(gloss.value - 100.0) <= 2 * gloss.u, gloss
    assert gloss.u < 0.5
