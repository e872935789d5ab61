"""Each family against an independent evaluation: Oren-Nayar and ABg written again in mpmath
from the papers' own angles (theta, phi, the direction cosines beta), Lambert as rho / pi, the
coated model from Walter's layer in mpmath (bsdf_reference) plus a base whose layer albedo comes
from hemisphere quadrature rather than the model's stratified visible-normal table."""

import bsdf_reference as ref
import mpmath as mp
import numpy as np
import pytest
from bsdf_quadrature import direction, integrate_sphere

from model.bsdf import ABg, CoatedDiffuse, Lambert, OrenNayar
from model.bsdf.families.abg import hyp_one

ANGLES = [(0.0, 0.0, 0.7, 2.0), (0.3, 0.0, 0.3, np.pi), (1.2, 0.4, 0.5, 0.4),
          (0.9, 0.1, 1.4, 1.9), (1.5, 0.0, 0.2, 3.0), (0.6, 2.0, 0.6, 2.0 + np.pi / 2)]


def _pair(theta_i, phi_i, theta_o, phi_o):
    return direction(theta_i, phi_i), direction(theta_o, phi_o)


def oren_nayar_mp(rho, sigma, variant, theta_i, phi_i, theta_r, phi_r):
    """Oren & Nayar 1994 in their variables: alpha = max, beta = min of the polar angles."""
    rho, s2 = mp.mpf(rho), mp.mpf(sigma) ** 2
    ti, tr, dphi = mp.mpf(theta_i), mp.mpf(theta_r), mp.mpf(phi_r) - mp.mpf(phi_i)
    a, b = max(ti, tr), min(ti, tr)
    if variant == "qualitative":
        return rho / mp.pi * (1 - s2 / (2 * (s2 + mp.mpf("0.33")))
                              + mp.mpf("0.45") * s2 / (s2 + mp.mpf("0.09"))
                              * max(0, mp.cos(dphi)) * mp.sin(a) * mp.tan(b))
    c1 = 1 - mp.mpf("0.5") * s2 / (s2 + mp.mpf("0.33"))
    if mp.cos(dphi) >= 0:
        c2 = mp.mpf("0.45") * s2 / (s2 + mp.mpf("0.09")) * mp.sin(a)
    else:
        c2 = mp.mpf("0.45") * s2 / (s2 + mp.mpf("0.09")) * (mp.sin(a) - (2 * b / mp.pi) ** 3)
    c3 = mp.mpf("0.125") * s2 / (s2 + mp.mpf("0.09")) * (4 * a * b / mp.pi**2) ** 2
    l1 = rho / mp.pi * (c1 + mp.cos(dphi) * c2 * mp.tan(b)
                        + (1 - abs(mp.cos(dphi))) * c3 * mp.tan((a + b) / 2))
    l2 = (mp.mpf("0.17") * rho**2 / mp.pi * s2 / (s2 + mp.mpf("0.13"))
          * (1 - mp.cos(dphi) * (2 * b / mp.pi) ** 2))
    return l1 + l2


def abg_mp(a, b, g, theta_i, phi_i, theta_s, phi_s):
    """OpticStudio's ABg from direction cosines: beta0 of the specular ray (azimuth phi_i + pi),
    beta of the scattered one."""
    beta0 = [mp.sin(theta_i) * mp.cos(phi_i + mp.pi), mp.sin(theta_i) * mp.sin(phi_i + mp.pi)]
    beta = [mp.sin(theta_s) * mp.cos(phi_s), mp.sin(theta_s) * mp.sin(phi_s)]
    x = mp.sqrt((beta[0] - beta0[0]) ** 2 + (beta[1] - beta0[1]) ** 2)
    return mp.mpf(a) / (mp.mpf(b) + x ** mp.mpf(g))


@pytest.mark.parametrize("angles", ANGLES)
@pytest.mark.parametrize("variant", ["full", "qualitative"])
@pytest.mark.parametrize("sigma", [0.0, 0.2, 0.6, 1.2])
def test_oren_nayar_matches_the_papers_formulas(angles, variant, sigma):
    wi, wo = _pair(*angles)
    got = OrenNayar(0.7, sigma, variant).eval(wi, wo)
    want = float(oren_nayar_mp(0.7, sigma, variant, *angles))
    assert got == pytest.approx(want, rel=1e-12)


@pytest.mark.parametrize("angles", ANGLES)
@pytest.mark.parametrize("abg", [(2e-3, 1e-3, 2.0), (0.05, 0.02, 1.5), (0.2, 0.0, 0.0),
                                 (0.01, 0.5, -1.0), (1e-4, 1e-9, 3.0)])
def test_abg_matches_opticstudios_definition(angles, abg):
    wi, wo = _pair(*angles)
    got = ABg(*abg).eval(wi, wo)
    assert got == pytest.approx(float(abg_mp(*abg, *angles)), rel=1e-11)


def test_lambert_is_rho_over_pi_above_and_zero_below():
    wi = direction(0.4)
    wo = np.array([direction(0.0), direction(1.5, 2.0), direction(2.0)])
    np.testing.assert_array_equal(Lambert(0.3).eval(wi, wo), [0.3 / np.pi] * 2 + [0.0])


def _layer_albedo(layer, mu):
    """Directional albedo of the layer at cosine mu by hemisphere quadrature of f cos."""
    wi = np.array([np.sqrt(1 - mu * mu), 0.0, mu])
    return integrate_sphere(lambda d: layer.eval(wi, d) * d[..., 2], nz=48, nphi=48, order=5,
                            z_range=(0.0, 1.0))


def test_coated_is_walters_layer_plus_the_kelemen_base():
    model = CoatedDiffuse(0.6, 0.3, 1.5)
    x, w = np.polynomial.legendre.leggauss(16)
    mu_nodes = 0.5 * (x + 1)
    mean = float(np.sum(w * mu_nodes * [_layer_albedo(model.layer, m) for m in mu_nodes]))
    for angles in ANGLES:
        wi, wo = _pair(*angles)
        layer = float(ref.eval_dielectric("ggx", (0.3, 0.3), 1.5, "separable", wi, wo,
                                          lobes=("reflection",)))
        base = (0.6 / np.pi * (1 - _layer_albedo(model.layer, wi[2]))
                * (1 - _layer_albedo(model.layer, wo[2])) / (1 - mean))
        assert model.eval(wi, wo) == pytest.approx(layer + base, rel=2e-4)


@pytest.mark.parametrize("c", [0.2, 1 - 1e-15, 1.0, 1 + 1e-9, 2 + 4e-16, 2.5, 3 + 1e-14, 7.999,
                               12.0, 1e3, 1e6])
def test_abg_hypergeometric_against_mpmath(c):
    """ABg's radial integral rests on 2F1(1, c; 1 + c; z), z <= 0: near-integer c and large c
    included, where scipy's hyp2f1 fails."""
    x = np.array([0.0, 1e-12, 0.5, 1.999, 2.0, 2.001, 1e3, 1e9, 1e15])
    want = [float(mp.hyp2f1(1, c, 1 + c, -mp.mpf(v))) for v in x]
    np.testing.assert_allclose(hyp_one(c, -x), want, rtol=1e-13)
