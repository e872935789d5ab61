"""energy_loss against an independent integral: nested adaptive scipy quadrature over the facet
normal's spherical angles, with its own D, Lambda and Fresnel formulas and root-found
breakpoints (energy.py integrates over unit-roughness slopes on fixed graded panels)."""
import numpy as np
import pytest
from scipy import integrate, optimize
from scipy.special import betaln, erfc

from model.bsdf.multiple_scattering import energy_loss


def lam(name, ax, ay, w):
    """Smith Lambda of an upward w (scalar formulas, not model.bsdf's)."""
    sin_t = np.hypot(w[0], w[1])
    if sin_t == 0.0:
        return 0.0
    alpha = np.sqrt((ax * w[0]) ** 2 + (ay * w[1]) ** 2) / sin_t
    a = w[2] / (alpha * sin_t)
    if name == "ggx":
        return 0.5 / (a * a) / (1.0 + np.sqrt(1.0 + 1.0 / (a * a)))
    return 0.5 * (np.exp(-a * a) / (a * np.sqrt(np.pi)) - erfc(a))


def ndf(name, ax, ay, t, p):
    tan2 = np.tan(t) ** 2 * (np.cos(p) ** 2 / ax**2 + np.sin(p) ** 2 / ay**2)
    c4 = np.cos(t) ** 4
    if name == "ggx":
        return 1.0 / (np.pi * ax * ay * c4 * (1.0 + tan2) ** 2)
    return np.exp(-tan2) / (np.pi * ax * ay * c4)


def fresnel(c, eta):
    g2 = eta * eta - 1.0 + c * c
    g = np.sqrt(g2)
    a = (g - c) / (g + c)
    b = (c * (g + c) - 1.0) / (c * (g - c) + 1.0)
    return 0.5 * a * a * (1.0 + b * b)


def loss(name, alpha, eta, theta, correlated=True):
    ax, ay = (alpha, alpha) if np.isscalar(alpha) else alpha
    wi = np.array([np.sin(theta), 0.0, np.cos(theta)])
    li = lam(name, ax, ay, wi)

    def normal(t, p):
        return np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])

    def lost(t, p):
        m = normal(t, p)
        c = wi @ m
        if c <= 0.0:
            return 0.0
        wr = 2 * c * m - wi
        if wr[2] <= 0.0:
            lr_part = 1.0
        else:
            lr = lam(name, ax, ay, wr)
            lr_part = lr / (1 + li + lr) if correlated else lr / (1 + lr)
        if eta is None:
            part = lr_part
        else:
            f = fresnel(c, eta)
            ct = np.sqrt(1 - (1 - c * c) / eta**2)
            wt = -wi / eta + (c / eta - ct) * m
            wt /= np.linalg.norm(wt)
            if wt[2] >= 0.0:
                lt_part = 1.0
            else:
                lt = lam(name, ax, ay, -wt)
                lt_part = (-np.expm1(np.log1p(li) + betaln(1 + li, 1 + lt)) if correlated
                           else lt / (1 + lt))
            part = f * lr_part + (1 - f) * lt_part
        return c * ndf(name, ax, ay, t, p) * np.sin(t) * part

    def inner(p):
        end = 0.5 * np.pi
        if np.cos(p) < 0 and theta > 0:
            end = np.arctan(-np.cos(theta) / (np.sin(theta) * np.cos(p)))
        points = []
        def wr_z(t):
            m = normal(t, p)
            return 2 * (wi @ m) * m[2] - wi[2]
        if wr_z(end * (1 - 1e-12)) < 0:
            points.append(optimize.brentq(wr_z, 0.0, end * (1 - 1e-12), xtol=1e-15))
        if eta is not None:
            def wt_z(t):
                m = normal(t, p)
                c = wi @ m
                ct = np.sqrt(1 - (1 - c * c) / eta**2)
                return (-wi / eta + (c / eta - ct) * m)[2]
            if wt_z(end * (1 - 1e-12)) > 0:
                points.append(optimize.brentq(wt_z, 0.0, end * (1 - 1e-12), xtol=1e-15))
        edges = [0.0] + sorted(points) + [end]
        return sum(integrate.quad(lost, a, b, args=(p,), epsabs=1e-13, epsrel=1e-7,
                                  limit=200)[0]
                   for a, b in zip(edges[:-1], edges[1:], strict=True) if b > a)

    total = integrate.quad(inner, 0.0, np.pi, epsabs=1e-12, epsrel=1e-6, limit=200,
                           points=[0.5 * np.pi])[0]
    return 2.0 * total / (np.cos(theta) * (1.0 + li))


CASES = [
    ("beckmann", 0.3, None, 0.0),  # issue 19: 1.89e-4 before, a 1-D integral 2.87e-4
    ("beckmann", 0.26, None, 0.0),  # 2.1e-5
    ("beckmann", 0.023, 1.51, 85.0),  # the anti-glare sample at 85 deg: -6 % before
    ("beckmann", 0.023, 1.51, 80.0),  # 8.9e-8: below the 1e-6 the scene's rule needs
    ("beckmann", 0.3, 1.51, 23.0),
    ("ggx", 0.02, 1.51, 30.0),  # 6.7e-5
    ("ggx", 0.1, 1.51, 0.0),
    ("ggx", 0.394, 1.51, 60.0),
    ("ggx", (1.0, 0.3), None, 40.0),
]


@pytest.mark.parametrize("name,alpha,eta,theta_deg", CASES)
def test_energy_loss_within_one_percent_of_an_independent_integral(name, alpha, eta, theta_deg):
    theta = np.radians(theta_deg)
    reference = loss(name, alpha, eta, theta)
    value = energy_loss(name, alpha, eta, theta)
    if reference >= 1e-6:
        assert value == pytest.approx(reference, rel=1e-2)
    else:
        assert abs(value - reference) < 1e-8


def test_separable_masking_loss_against_the_independent_integral():
    theta = np.radians(70.0)
    reference = loss("ggx", 0.2, 1.51, theta, correlated=False)
    assert energy_loss("ggx", 0.2, 1.51, theta, masking="separable") == pytest.approx(
        reference, rel=1e-2)


def test_energy_loss_rejects_bad_incidence():
    with pytest.raises(ValueError, match="theta must lie"):
        energy_loss("ggx", 0.3, 1.5, 0.5 * np.pi)
