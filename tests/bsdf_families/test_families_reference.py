"""Each family against an independent evaluation: Oren-Nayar and ABg written again in mpmath
from the papers' own angles (theta, phi, the direction cosines beta), Lambert as rho / pi, the
coated model from Walter's layer in mpmath (bsdf_reference) plus a base whose layer albedo comes
from hemisphere quadrature rather than the model's stratified visible-normal table, Rayleigh-Rice
in Stover's angles (theta_s, phi_s from the plane of incidence, f_x and f_y) with the ABC PSD."""

import bsdf_reference as ref
import mpmath as mp
import numpy as np
import pytest
from bsdf_quadrature import direction, integrate_sphere

from model.bsdf import ABg, CoatedDiffuse, Lambert, OrenNayar, RayleighRice
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


def rayleigh_rice_mp(sigma_nm, b_um, c, lam_nm, eta, k, theta_i, phi_i, theta_s, phi_o):
    """BRDF = 16 pi^2 / lambda^4 cos_i cos_s Q S(f_x, f_y), with phi_s measured from the
    specular half of the plane of incidence (azimuth phi_i + pi), f_x = (sin theta_s cos phi_s
    - sin theta_i) / lambda, f_y = sin theta_s sin phi_s / lambda, Q = (Q_ss + Q_sp + Q_ps +
    Q_pp) / 2 and Church's ABC PSD A / (1 + (B f)^2)^((C+1)/2), A = sigma^2 B^2 (C-1) / (2 pi);
    lengths in um."""
    sigma, b, c = mp.mpf(sigma_nm) / 1000, mp.mpf(b_um), mp.mpf(c)
    lam = mp.mpf(lam_nm) / 1000
    ti, ts = mp.mpf(theta_i), mp.mpf(theta_s)
    phi = mp.mpf(phi_o) - mp.mpf(phi_i) - mp.pi
    fx = (mp.sin(ts) * mp.cos(phi) - mp.sin(ti)) / lam
    fy = mp.sin(ts) * mp.sin(phi) / lam
    a = sigma**2 * b**2 * (c - 1) / (2 * mp.pi)
    psd = a / (1 + b**2 * (fx**2 + fy**2)) ** ((c + 1) / 2)
    eps = mp.mpc(eta, k) ** 2
    qi, qs = mp.sqrt(eps - mp.sin(ti) ** 2), mp.sqrt(eps - mp.sin(ts) ** 2)
    ci, cs = mp.cos(ti), mp.cos(ts)
    q_ss = abs((eps - 1) * mp.cos(phi) / ((ci + qi) * (cs + qs))) ** 2
    q_sp = abs((eps - 1) * qs * mp.sin(phi) / ((ci + qi) * (eps * cs + qs))) ** 2
    q_ps = abs((eps - 1) * qi * mp.sin(phi) / ((eps * ci + qi) * (cs + qs))) ** 2
    q_pp = abs((eps - 1) * (qi * qs * mp.cos(phi) - eps * mp.sin(ti) * mp.sin(ts))
               / ((eps * ci + qi) * (eps * cs + qs))) ** 2
    q = (q_ss + q_sp + q_ps + q_pp) / 2
    return 16 * mp.pi**2 / lam**4 * ci * cs * q * psd


RAYLEIGH_RICE = [(1.0, 2.0, 2.0, 632.8, 1.5, 0.0), (3.0, 0.4, 1.2, 1064.0, 0.2, 6.9),
                 (0.3, 50.0, 4.0, 10600.0, 25.0, 60.0), (2.0, 5.0, 3.0, 405.0, 1.0001, 0.0)]


@pytest.mark.parametrize("angles", ANGLES)
@pytest.mark.parametrize("params", RAYLEIGH_RICE)
def test_rayleigh_rice_matches_stovers_form(angles, params):
    wi, wo = _pair(*angles)
    got = RayleighRice(*params).eval(wi, wo)
    assert got == pytest.approx(float(rayleigh_rice_mp(*params, *angles)), rel=1e-11)


@pytest.mark.parametrize("params", RAYLEIGH_RICE)
@pytest.mark.parametrize("theta_i", [0.0, 0.4, 1.1, 1.5])
def test_rayleigh_rice_q_at_the_mirror_direction_is_the_fresnel_reflectance(params, theta_i):
    """Q(i, mirror of i) = (|r_s|^2 + |r_p|^2) / 2 of the flat surface, written from Snell's
    law: r_s = (cos_i - n cos_t) / (cos_i + n cos_t), r_p = (n cos_i - cos_t) / (n cos_i +
    cos_t); so f / (16 pi^2 cos_i^2 S(0) / lambda^4) there is R."""
    sigma_nm, b_um, c, lam_nm, eta, k = params
    n, ti = mp.mpc(eta, k), mp.mpf(theta_i)
    cos_t = mp.sqrt(1 - (mp.sin(ti) / n) ** 2)
    r_s = (mp.cos(ti) - n * cos_t) / (mp.cos(ti) + n * cos_t)
    r_p = (n * mp.cos(ti) - cos_t) / (n * mp.cos(ti) + cos_t)
    fresnel = (abs(r_s) ** 2 + abs(r_p) ** 2) / 2
    at_mirror = rayleigh_rice_mp(*params, theta_i, 0.3, theta_i, 0.3 + mp.pi)
    lam, sigma, b = mp.mpf(lam_nm) / 1000, mp.mpf(sigma_nm) / 1000, mp.mpf(b_um)
    psd0 = sigma**2 * b**2 * (c - 1) / (2 * mp.pi)
    assert float(at_mirror / (16 * mp.pi**2 / lam**4 * mp.cos(ti) ** 2 * psd0)) == \
        pytest.approx(float(fresnel), rel=1e-12)
    wi = direction(theta_i, 0.3)
    mirror = np.array([-wi[0], -wi[1], wi[2]])
    assert RayleighRice(*params).eval(wi, mirror) == pytest.approx(float(at_mirror), rel=1e-11)


def test_abc_psd_integrates_to_sigma_squared():
    """The ABC normalisation A = sigma^2 B^2 (C - 1) / (2 pi) gives int S d^2f = sigma^2 (mpmath
    quadrature of 2 pi f S(f)), and KCorrelationPSD.from_abc inverts it."""
    from model.bsdf.diffraction import KCorrelationPSD

    sigma, b, c = mp.mpf("1e-9"), mp.mpf("2e-6"), mp.mpf("2.5")
    a = sigma**2 * b**2 * (c - 1) / (2 * mp.pi)
    total = mp.quad(lambda f: 2 * mp.pi * f * a / (1 + (b * f) ** 2) ** ((c + 1) / 2),
                    [0, 1 / b, 100 / b, mp.inf])
    assert float(total / sigma**2) == pytest.approx(1.0, rel=1e-12)
    psd = KCorrelationPSD.from_abc(float(a), float(b), float(c))
    assert psd.sigma == pytest.approx(1e-9, rel=1e-14)
    np.testing.assert_allclose(psd.abc(), (float(a), 2e-6, 2.5), rtol=1e-14)
