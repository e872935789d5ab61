"""Physics of the model: white furnace, reciprocity, the alpha -> 0 Fresnel limit, D normalisation
and the projected-area identity (independent quadratures against closed forms)."""

import numpy as np
import pytest
from bsdf_quadrature import direction, integrate_sphere

from model.bsdf import (
    RoughConductor,
    RoughDielectric,
    fresnel_conductor,
    fresnel_dielectric,
    make_distribution,
)
from model.bsdf.distributions import DISTRIBUTION_NAMES as DISTS
from model.bsdf.masking import MASKINGS


def _mc_albedo(model, wi, n=100_000, seed=2):
    u = np.random.default_rng(seed).random((n, 3))
    weight = model.sample(wi, u)[1]
    return weight.mean(), weight.std() / np.sqrt(n)


@pytest.mark.parametrize("dist", DISTS)
@pytest.mark.parametrize("masking", MASKINGS)
@pytest.mark.parametrize("alpha,theta", [(0.3, 0.6), (0.8, 1.3), (0.5, np.pi - 0.5)])
def test_white_furnace_dielectric(dist, masking, alpha, theta):
    """Albedo = integral of f |cos o| <= 1, and the quadrature agrees with the sampled estimate."""
    sampling = "walter" if dist == "phong" else "visible"
    model = RoughDielectric(dist, alpha, 1.51, masking=masking, sampling=sampling)
    wi = direction(theta, 0.3)
    quad = integrate_sphere(lambda d: model.eval(wi, d) * np.abs(d[..., 2]))
    mc, err = _mc_albedo(model, wi)
    assert quad <= 1.0 + 1e-3 and mc <= 1.0
    assert abs(quad - mc) < 5 * err + 2e-3


@pytest.mark.parametrize("masking", MASKINGS)
@pytest.mark.parametrize("dist", ["ggx", "beckmann"])
def test_white_furnace_conductor_tends_to_one(dist, masking):
    """F = 1: albedo < 1 (single scattering loses energy) and -> 1 as alpha -> 0."""
    wi = direction(1.0, 0.2)
    albedos = [_mc_albedo(RoughConductor(dist, a, None, masking=masking), wi)[0]
               for a in (1.0, 0.3, 0.1, 1e-2, 1e-4)]
    assert all(a <= 1.0 for a in albedos)
    assert np.all(np.diff(albedos) > -1e-3)
    assert albedos[-1] > 1 - 1e-3
    quad = integrate_sphere(lambda d: RoughConductor(dist, 0.3, None, masking=masking)
                            .eval(wi, d) * np.abs(d[..., 2]), z_range=(0.0, 1.0))
    assert abs(quad - albedos[1]) < 3e-3


@pytest.mark.parametrize("dist", DISTS)
@pytest.mark.parametrize("masking", MASKINGS)
def test_reciprocity(dist, masking):
    """f_r(i,o) = f_r(o,i); f_t(i,o) / eta_o^2 = f_t(o,i) / eta_i^2 (Walter eq. 21)."""
    eta = 1.51
    alpha = 0.4 if dist == "phong" else (0.3, 0.5) if dist != "phong" else 0.4
    model = RoughDielectric(dist, alpha, eta, masking=masking, sampling="walter")
    rng = np.random.default_rng(4)
    a = rng.normal(size=(2000, 3))
    b = rng.normal(size=(2000, 3))
    a[:, 2] = np.abs(a[:, 2])  # exterior
    f_ab, f_ba = model.eval(a, b), model.eval(b, a)
    refl = b[:, 2] > 0
    np.testing.assert_allclose(f_ab[refl], f_ba[refl], rtol=1e-12)
    # a outside (eta_a = 1), b inside (eta_b = eta)
    np.testing.assert_allclose(f_ab[~refl] / eta**2, f_ba[~refl], rtol=1e-12, atol=1e-300)
    assert np.count_nonzero(f_ab[~refl]) > 100  # the transmission side was really exercised


@pytest.mark.parametrize("theta", [0.0, 0.5, 1.0, 1.4, np.pi - 0.2, np.pi - 0.9])
@pytest.mark.parametrize("eta", [1.51, 1 / 1.33])
def test_smooth_limit_is_fresnel(theta, eta):
    """alpha -> 0: reflected albedo -> F(theta), transmitted -> 1 - F (TIR included)."""
    wi = direction(theta, 0.5)
    fresnel = float(fresnel_dielectric(wi[2], eta))
    refl = RoughDielectric("ggx", 1e-4, eta, lobes=("reflection",))
    trans = RoughDielectric("ggx", 1e-4, eta, lobes=("transmission",))
    assert _mc_albedo(refl, wi, n=20_000)[0] == pytest.approx(fresnel, abs=1e-3)
    assert _mc_albedo(trans, wi, n=20_000)[0] == pytest.approx(1 - fresnel, abs=1e-3)


def test_smooth_limit_conductor():
    eta = 0.18 + 3.4j
    for theta in (0.0, 0.7, 1.3):
        wi = direction(theta)
        model = RoughConductor("beckmann", 1e-4, eta)
        expected = float(fresnel_conductor(np.cos(theta), eta))
        assert _mc_albedo(model, wi, n=20_000)[0] == pytest.approx(expected, abs=1e-3)


def _tan_nodes(scale, n, lo=-1.0, hi=1.0):
    """Gauss-Legendre nodes of t in (lo, hi) mapped to s = scale tan(pi t / 2), with weights ds."""
    t, w = np.polynomial.legendre.leggauss(n)
    t = lo + (hi - lo) * 0.5 * (t + 1)
    w = w * 0.5 * (hi - lo)
    return scale * np.tan(0.5 * np.pi * t), w * scale * 0.5 * np.pi / np.cos(0.5 * np.pi * t) ** 2


def _slope_integral(d, g, w_dir=None, n=300):
    """Integral over the slope plane of g(m) P22(s), P22 = D(m) m.z^4 the slope density.

    Done in the stretched slope plane (slopes / alpha), on Cartesian axes along and across
    the stretched azimuth of w_dir; with w_dir given the plane is cut at the horizon of w_dir
    (w.m = 0, where the integrand has its kink) and only the visible side is integrated, so
    Gauss-Legendre stays accurate.
    """
    ax, ay = float(d.alpha_x), float(d.alpha_y)
    wxy = 0.0 if w_dir is None else float(np.hypot(ax * w_dir[0], ay * w_dir[1]))
    cphi, sphi = (ax * w_dir[0] / wxy, ay * w_dir[1] / wxy) if wxy > 0 else (1.0, 0.0)
    perp, w_perp = _tan_nodes(1.0, n)
    if wxy == 0:
        pieces = [_tan_nodes(1.0, n)]
    else:  # u_par in (-inf, 0] and [0, c], c = w.z / |w_xy| (stretched) the horizon of w_dir
        c = w_dir[2] / wxy
        t, w = np.polynomial.legendre.leggauss(n)
        u = 0.5 * (t + 1) * np.arctan(c)
        pieces = [_tan_nodes(1.0, n, -1.0, 0.0),
                  (np.tan(u), 0.5 * w * np.arctan(c) / np.cos(u) ** 2)]
    total = 0.0
    for par, w_par in pieces:
        sx = ax * (par[:, None] * cphi - perp[None, :] * sphi)
        sy = ay * (par[:, None] * sphi + perp[None, :] * cphi)
        m = np.stack([-sx, -sy, np.ones_like(sx)], -1)
        m /= np.linalg.norm(m, axis=-1, keepdims=True)
        weight = ax * ay * w_par[:, None] * w_perp[None, :]
        total += np.sum(weight * g(m) * d.D(m) * m[..., 2] ** 4)
    return total


CASES = [("ggx", 1e-3), ("ggx", 0.3), ("ggx", (0.1, 2.0)), ("ggx", 4.0),
         ("beckmann", 1e-3), ("beckmann", 0.5), ("beckmann", (1.5, 0.2)), ("beckmann", 4.0),
         ("phong", 1e-2), ("phong", 0.4), ("phong", 0.9)]


@pytest.mark.parametrize("name,alpha", CASES)
def test_distribution_normalised(name, alpha):
    """Integral of D(m) m.n over the hemisphere = 1 (slope-plane quadrature)."""
    d = make_distribution(name, alpha)
    assert _slope_integral(d, lambda m: 1.0) == pytest.approx(1.0, abs=1e-8)


@pytest.mark.parametrize("alpha", [1.2, 4.0])
def test_phong_normalised_beyond_alpha_one(alpha):
    """Phong with alpha > 1 has a negative exponent (D integrably infinite at the horizon)."""
    d = make_distribution("phong", alpha)
    v, w = np.polynomial.legendre.leggauss(200)
    v = 0.5 * (v + 1)  # cos theta = v^8 removes the horizon singularity of the integrand
    x = v**8
    m = np.stack([np.sqrt(1 - x * x), 0 * x, x], -1)
    integral = 2 * np.pi * np.sum(0.5 * w * d.D(m) * x * 8 * v**7)
    assert integral == pytest.approx(1.0, abs=1e-9)


@pytest.mark.parametrize("name,alpha", CASES)
@pytest.mark.parametrize("theta,phi", [(0.0, 0.0), (0.6, 0.3), (1.2, 2.0), (1.55, 1.0)])
def test_projected_area_identity(name, alpha, theta, phi):
    """Integral of G1(w, m) max(0, w.m) D(m) dm = cos theta_w (exact Smith G1 for all three).

    The tolerance is the quadrature's: GGX and Phong slope tails (s^-4) leave ~1e-5 at 300 nodes."""
    d = make_distribution(name, alpha)
    wv = direction(theta, phi)
    integral = _slope_integral(d, lambda m: d.G1(wv, m) * np.maximum(0, m @ wv) / m[..., 2], wv)
    assert integral == pytest.approx(wv[2], rel=1e-8 if name == "beckmann" else 2e-5, abs=1e-12)
