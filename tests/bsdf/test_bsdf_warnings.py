"""No RuntimeWarning leaks from the model at its edge inputs (N.V exactly 0, eta exactly 1,
subnormal cosines, Phong over the fit's alpha range, u1 = 1): every call runs with warnings
turned into errors, and the values are checked too."""

import warnings

import numpy as np
import pytest

from model.bsdf import RoughConductor, RoughDielectric, make_distribution
from model.bsdf.fresnel import (
    dielectric_reflectance_transmittance,
    dielectric_transmittance,
    fresnel_conductor,
    fresnel_dielectric,
)
from model.bsdf.masking import g2_over_cosines

GRAZING = np.array([[1.0, 0.0, 0.0], [0.6, 0.8, 0.0], [0.6, 0.8, -0.0]])
OTHER = np.array([[0.3, 0.0, 0.954], [0.0, 0.0, 1.0], [0.3, 0.1, -0.95]])
COSINES = np.array([0.0, -0.0, 5e-324, -5e-324, 1e-300, -1e-300, 1e-9, 0.5, 1.0, -1.0])


@pytest.fixture(autouse=True)
def warnings_are_errors():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        yield


@pytest.mark.parametrize("backend", ["numpy", None])
@pytest.mark.parametrize("masking", ["separable", "correlated"])
@pytest.mark.parametrize("dist", ["ggx", "beckmann", "phong"])
def test_model_at_grazing_with_index_matched_interface(dist, masking, backend):
    sampling = "walter" if dist == "phong" else "visible"
    u = np.random.default_rng(0).random((3, 3))
    for eta in (1.0, 1.0 + 1e-12):
        model = RoughDielectric(dist, 0.3, eta, masking=masking, sampling=sampling,
                                backend=backend)
        for wi, wo in ((GRAZING, OTHER), (OTHER, GRAZING), (GRAZING, GRAZING),
                       (GRAZING, -GRAZING)):
            assert np.all(model.eval(wi, wo) == 0) and np.all(model.pdf(wi, wo) == 0)
        wo, weight, pdf = model.sample(GRAZING, u)
        assert np.all(weight == 0) and np.all(pdf == 0) and np.all(wo == 0)
        conductor = RoughConductor(dist, 0.3, complex(eta, 0.0), masking=masking,
                                   sampling=sampling, backend=backend)
        assert np.all(conductor.eval(GRAZING, OTHER) == 0)
        assert np.all(conductor.sample(GRAZING, u)[1] == 0)


def test_masking_at_zero_cosines_and_infinite_lambda():
    """G2 / (cos cos): +inf where both cosines are 0 (it diverges there), 0 where Lambda is
    infinite, finite otherwise; overflow past 1.8e308 gives inf, not a warning."""
    for transmitted in (False, True):
        assert g2_over_cosines("correlated", 0.0, 0.0, 0.2, 0.3, transmitted) == (
            0.0 if transmitted else np.inf)  # Beta: B(inf, inf) / (0 * 0) -> 0 (not live)
        for masking in ("separable", "correlated"):
            assert g2_over_cosines(masking, 0.0, 0.5, np.inf, 0.1, transmitted) == 0
            assert g2_over_cosines(masking, 0.5, 0.0, 0.1, np.inf, transmitted) == 0
            assert np.isfinite(g2_over_cosines(masking, 0.0, 0.5, 0.2, 0.1, transmitted))
    assert g2_over_cosines("correlated", 1e-300, 1e-300, 0.0, 0.0, True) == np.inf
    assert g2_over_cosines("separable", 1e-300, 1e-300, 0.0, 0.0) == np.inf


@pytest.mark.parametrize("eta", [1.0, 1.0 - 1e-12, 1.0 + 1e-12, 1.51, 1 / 1.51])
def test_fresnel_at_zero_and_subnormal_cosines(eta):
    f, t = dielectric_reflectance_transmittance(COSINES, eta)
    assert np.all((f >= 0) & (f <= 1) & (t >= 0) & (t <= 1 + 1e-15))
    assert np.array_equal(fresnel_dielectric(COSINES, eta), f)
    if eta == 1.0:  # matched: all transmitted down to c ~ 1e-154 (where c^2 underflows)
        assert np.all(f[np.abs(COSINES) >= 1e-9] == 0) and np.all(f[COSINES == 0] == 1)
    c = np.abs(COSINES)
    ct = dielectric_transmittance(c, c, 1.0)  # same cosine both sides at e = 1: T = 1
    np.testing.assert_allclose(ct[c > 0], 1.0, rtol=1e-15)
    assert np.all(ct[c == 0] == 0)
    fc = fresnel_conductor(COSINES, complex(eta, 0.0))
    assert np.all((fc >= 0) & (fc <= 1 + 1e-15))
    if eta == 1.0:
        assert np.all(fc[c > 0] == 0)


@pytest.mark.parametrize("alpha", [1e-4, 0.023, 0.3, 1.0, 1.3, np.sqrt(2.0), 2.0, 4.0])
def test_phong_over_the_fit_range(alpha):
    """The fits vary Phong's alpha over [1e-4, 4] (exponent from 2e8 down to -1.875)."""
    d = make_distribution("phong", alpha)
    z = np.array([0.0, 5e-324, 1e-300, 1e-9, 0.3, 0.7, 1.0 - 1e-16, 1.0])
    w = np.stack([np.sqrt(1.0 - z * z), np.zeros_like(z), z], axis=-1)
    for values in (d.D(w), d.Lambda(w), d.cos_lambda(w), d.pdf_normal(w),
                   d.G1(w, np.array([0.0, 0.0, 1.0]))):
        assert np.all(values >= 0)
    u1 = np.array([0.0, 0.5, 1.0 - 2.0**-53, 1.0])
    m = d.sample_normal(u1, np.full(4, 0.25))
    assert np.all(np.isfinite(m))
    np.testing.assert_allclose(m[-1], [0.0, 1.0, 0.0], atol=1e-16)  # u1 = 1: the horizon
