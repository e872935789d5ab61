"""The Mueller BSDF in the smooth limit (alpha = 1e-4): integrated over its specular or refracted
lobe it is a flat interface's Mueller matrix, checked against Fresnel's formulas written out
here, Brewster's angle, and Maxwell's boundary conditions (maxwell_interface) for the phases
(a conductor's retardance, total internal reflection)."""

import numpy as np
import pytest
from maxwell_interface import interface_mueller
from scipy.optimize import minimize_scalar

from model.bsdf import RoughConductor, RoughDielectric
from model.bsdf.mueller import stokes_frame

ALPHA = 1e-4
GOLD_633 = 0.18 + 3.43j  # Johnson & Christy, 633 nm
ALUMINIUM_633 = 1.37 + 7.62j  # Rakic, 633 nm


def lobe_integral(model, theta_i: float, transmitted: bool = False, inside: bool = False
                  ) -> np.ndarray:
    """int M(wi, wo) |cos o| d omega (4, 4) over a disk in the plane of the direction cosines
    (d^2 beta = |cos o| d omega) about the mirror or refracted direction, of radius 8 alpha s:
    a facet tilted by t moves beta by s t, s = 2 cos i (reflection) or |cos i - e cos t| / e
    (refraction), and Beckmann's slopes have deviation alpha / sqrt 2 (11 of them)."""
    eta = getattr(model, "eta", 1.0)
    e = 1.0 / eta if inside else eta
    side = -1.0 if inside else 1.0
    wi = np.array([np.sin(theta_i), 0.0, side * np.cos(theta_i)])
    centre = -wi[:2] / (e if transmitted else 1.0)
    cos_i = np.cos(theta_i)
    spread = (abs(cos_i - np.sqrt(e * e - np.sin(theta_i) ** 2)) / e if transmitted
              else 2 * cos_i)
    radius = 8 * ALPHA * spread
    x, w = np.polynomial.legendre.leggauss(12)
    cells = np.linspace(0.0, radius, 9)
    r = (cells[:-1, None] + 0.5 * np.diff(cells)[:, None] * (x + 1)).ravel()
    wr = (0.5 * np.diff(cells)[:, None] * w).ravel() * r
    phi = np.linspace(0, 2 * np.pi, 97)[:-1]
    beta = centre + r[:, None, None] * np.stack([np.cos(phi), np.sin(phi)], -1)[None]
    z = np.sqrt(1.0 - np.sum(beta**2, -1)) * (-side if transmitted else side)
    wo = np.concatenate([beta, z[..., None]], -1)
    muellers = model.eval_mueller(wi, wo)
    return np.einsum("ra...,r->...", muellers, wr) * (2 * np.pi / len(phi))


def fresnel_rs_rp(theta_i: float, n: complex) -> tuple[complex, complex]:
    """Textbook amplitudes (Born & Wolf 1.5.2): r_s = (cos i - n cos t)/(cos i + n cos t),
    r_p = (n cos i - cos t)/(n cos i + cos t), cos t = sqrt(1 - sin^2 i / n^2)."""
    ci = np.cos(theta_i)
    ct = np.sqrt(1 - np.sin(theta_i) ** 2 / complex(n) ** 2)
    return (ci - n * ct) / (ci + n * ct), (n * ci - ct) / (n * ci + ct)


@pytest.mark.parametrize("theta_deg", [0.0, 20.0, 45.0, 56.0, 70.0, 80.0])
@pytest.mark.parametrize("eta", [1.51, 1.0 / 1.33])
def test_reflection_gives_fresnel_rs_rp(theta_deg, eta):
    """M00 = (Rs + Rp)/2, M01 = M10 = (Rs - Rp)/2 with S1 = I_s - I_p (docs/bsdf.md)."""
    theta = np.radians(theta_deg)
    m = lobe_integral(RoughDielectric("beckmann", ALPHA, eta), theta)
    rs, rp = fresnel_rs_rp(theta, eta)
    big_rs, big_rp = abs(rs) ** 2, abs(rp) ** 2
    assert m[0, 0] == pytest.approx((big_rs + big_rp) / 2, rel=1e-4, abs=1e-7)
    assert m[0, 1] == pytest.approx((big_rs - big_rp) / 2, rel=1e-4, abs=1e-7)
    assert m[1, 0] == pytest.approx((big_rs - big_rp) / 2, rel=1e-4, abs=1e-7)


@pytest.mark.parametrize("theta_deg", [5.0, 30.0, 60.0, 80.0])
@pytest.mark.parametrize("inside", [False, True])
def test_transmission_gives_fresnel_ts_tp(theta_deg, inside):
    """Transmitted: M00 = (Ts + Tp)/2, M01 = (Ts - Tp)/2, M22 = M33 = sqrt(Ts Tp), with
    Ts = 1 - Rs, Tp = 1 - Rp (no phase between t_s and t_p). Not at 0: a lobe about the
    normal averages wo's s/p frame over all azimuths (docs/bsdf.md, Polarisation)."""
    theta = np.radians(theta_deg if not inside else min(theta_deg, 40.0))  # below critical
    model = RoughDielectric("beckmann", ALPHA, 1.51)
    m = lobe_integral(model, theta, transmitted=True, inside=inside)
    rs, rp = fresnel_rs_rp(theta, 1 / 1.51 if inside else 1.51)
    ts, tp = 1 - abs(rs) ** 2, 1 - abs(rp) ** 2
    expected = np.array([[ts + tp, ts - tp, 0, 0], [ts - tp, ts + tp, 0, 0],
                         [0, 0, 2 * np.sqrt(ts * tp), 0], [0, 0, 0, 2 * np.sqrt(ts * tp)]]) / 2
    np.testing.assert_allclose(m, expected, rtol=0, atol=2e-4)


@pytest.mark.parametrize("eta,inside", [(1.51, False), (1.51, True), (2.4, False)])
def test_p_reflectance_has_its_minimum_at_brewster(eta, inside):
    """Incident p (S = (1, -1, 0, 0)): reflected power M00 - M01 is least at arctan(n) (n the
    index toward which the light goes), where it is ~0 against Rs."""
    model = RoughDielectric("beckmann", ALPHA, eta)

    def p_reflectance(theta):
        m = lobe_integral(model, theta, inside=inside)
        return m[0, 0] - m[0, 1]

    best = minimize_scalar(p_reflectance, bounds=(np.radians(20), np.radians(75)),
                           method="bounded", options={"xatol": 1e-8})
    n = 1 / eta if inside else eta
    assert np.degrees(best.x) == pytest.approx(np.degrees(np.arctan(n)), abs=2e-3)
    m = lobe_integral(model, best.x, inside=inside)
    assert best.fun < 1e-6 * (m[0, 0] + m[0, 1])


@pytest.mark.parametrize("n", [GOLD_633, ALUMINIUM_633, 1.51 + 0j])
@pytest.mark.parametrize("theta_deg", [10.0, 45.0, 70.0, 85.0])
def test_conductor_mirror_mueller_matches_maxwell(n, theta_deg):
    """All 16 elements, with the retardance M23 = -M32 of a metal's s/p phase, against the
    fields solved from the boundary conditions, read in the frames docs/bsdf.md states."""
    theta = np.radians(theta_deg)
    model = RoughConductor("beckmann", ALPHA, n) if n.imag else RoughDielectric(
        "beckmann", ALPHA, n.real, lobes=("reflection",))
    m = lobe_integral(model, theta)
    wi = np.array([np.sin(theta), 0.0, np.cos(theta)])
    wo = np.array([-wi[0], 0.0, wi[2]])
    exact = interface_mueller(-wi, np.array([0.0, 0.0, 1.0]), n, stokes_frame(-wi),
                              stokes_frame(wo))
    np.testing.assert_allclose(m, exact, rtol=0, atol=2e-4 * exact[0, 0])
    rs, rp = fresnel_rs_rp(theta, n)
    assert m[0, 0] == pytest.approx((abs(rs) ** 2 + abs(rp) ** 2) / 2, rel=1e-4)
    if n.imag and theta_deg >= 45:
        assert abs(m[2, 3]) > 0.1 * m[0, 0] and m[3, 2] == pytest.approx(-m[2, 3], rel=1e-6)
        assert m[3, 2] == pytest.approx((np.conj(rs) * rp).imag, rel=1e-3)


@pytest.mark.parametrize("theta_deg", [45.0, 60.0, 80.0])
def test_total_internal_reflection_is_a_retarder_as_maxwell_says(theta_deg):
    """From inside glass beyond the critical angle: all power reflected, s and p out of phase
    (M22 = M33 < 1, M23 = -M32 != 0), against the boundary-condition solution."""
    theta = np.radians(theta_deg)
    m = lobe_integral(RoughDielectric("beckmann", ALPHA, 1.51), theta, inside=True)
    wi = np.array([np.sin(theta), 0.0, -np.cos(theta)])
    wo = np.array([-wi[0], 0.0, wi[2]])
    exact = interface_mueller(-wi, np.array([0.0, 0.0, 1.0]), 1 / 1.51, stokes_frame(-wi),
                              stokes_frame(wo))
    np.testing.assert_allclose(m, exact, rtol=0, atol=2e-4)
    assert m[0, 0] == pytest.approx(1.0, abs=2e-4) and abs(m[2, 3]) > 0.05
