"""An independent energy_loss: nested adaptive scipy quadrature over the facet normal's spherical
angles, with its own D, Lambda and Fresnel formulas (total internal reflection included) and
root-found breakpoints (energy.py integrates over unit-roughness slopes on fixed graded panels).
Shared by tests/bsdf_ms/test_ms_energy.py and bench/energy_loss_accuracy.py."""
from __future__ import annotations

import numpy as np
from scipy import integrate, optimize
from scipy.special import betaln, erfc

#: Points per azimuth where the breakpoints are looked for by sign changes, and the scales of
#: the slope lobe (multiples of alpha) the inner integral is split at.
SCAN_POINTS = 256
LOBE_SCALES = 2.0 ** np.arange(-3, 12)


def lam(name: str, ax: float, ay: float, w: np.ndarray) -> float:
    """Smith Lambda of an upward w (scalar formulas, not model.bsdf's)."""
    sin_t = np.hypot(w[0], w[1])
    if sin_t == 0.0:
        return 0.0
    alpha = np.sqrt((ax * w[0]) ** 2 + (ay * w[1]) ** 2) / sin_t
    a = w[2] / (alpha * sin_t)
    if name == "ggx":
        return 0.5 / (a * a) / (1.0 + np.sqrt(1.0 + 1.0 / (a * a)))
    return 0.5 * (np.exp(-a * a) / (a * np.sqrt(np.pi)) - erfc(a))


def ndf(name: str, ax: float, ay: float, t: float, p: float) -> float:
    """D of the normal at polar angle t, azimuth p."""
    tan2 = np.tan(t) ** 2 * (np.cos(p) ** 2 / ax**2 + np.sin(p) ** 2 / ay**2)
    c4 = np.cos(t) ** 4
    if name == "ggx":
        return 1.0 / (np.pi * ax * ay * c4 * (1.0 + tan2) ** 2)
    return np.exp(-tan2) / (np.pi * ax * ay * c4)


def fresnel(c: float, eta: float) -> float:
    """Unpolarised reflectance at cosine c toward relative index eta (1 beyond the critical
    angle when eta < 1)."""
    g2 = eta * eta - 1.0 + c * c
    if g2 <= 0.0:
        return 1.0
    g = np.sqrt(g2)
    a = (g - c) / (g + c)
    b = (c * (g + c) - 1.0) / (c * (g - c) + 1.0)
    return 0.5 * a * a * (1.0 + b * b)


def _normal(t: float, p: float) -> np.ndarray:
    return np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])


def _refracted_z(wi: np.ndarray, m: np.ndarray, eta: float) -> float:
    """z of the refracted direction through m (nan under total internal reflection)."""
    c = wi @ m
    ct2 = 1 - (1 - c * c) / eta**2
    if ct2 < 0.0:
        return np.nan
    return (-wi / eta + (c / eta - np.sqrt(ct2)) * m)[2]


def _sign_changes(f, end: float) -> list[float]:
    """Roots of f on (0, end) where its sign (nan counted as its own sign) changes on a scan."""
    t = end * np.linspace(0.0, 1.0, SCAN_POINTS + 1)[1:-1]
    t = np.unique(np.concatenate([t, np.minimum(np.arctan(LOBE_SCALES), end) * 0.999999]))
    v = np.array([f(x) for x in t])
    s = np.where(np.isnan(v), 2, np.sign(v))
    roots = []
    for a, b, fa, fb, sa, sb in zip(t[:-1], t[1:], v[:-1], v[1:], s[:-1], s[1:], strict=True):
        if sa == sb:
            continue
        if np.isnan(fa) or np.isnan(fb):  # the total-internal-reflection edge: bisect on nan
            for _ in range(60):
                mid = 0.5 * (a + b)
                a, b = (mid, b) if np.isnan(f(mid)) == np.isnan(fa) else (a, mid)
            roots.append(0.5 * (a + b))
        else:
            roots.append(optimize.brentq(f, a, b, xtol=1e-15))
    return roots


def loss(name: str, alpha, eta: float | None, theta: float, correlated: bool = True) -> float:
    """Energy the single-scattering model misses at incidence theta (eta None: F = 1)."""
    ax, ay = (alpha, alpha) if np.isscalar(alpha) else alpha
    wi = np.array([np.sin(theta), 0.0, np.cos(theta)])
    li = lam(name, ax, ay, wi)

    def lost(t, p):
        m = _normal(t, p)
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
            lt_part = 0.0
            if f < 1.0:
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

    scale = np.sqrt(ax * ay)

    def inner(p):
        end = 0.5 * np.pi
        if np.cos(p) < 0 and theta > 0:
            end = np.arctan(-np.cos(theta) / (np.sin(theta) * np.cos(p)))
        points = _sign_changes(lambda t: 2 * (wi @ _normal(t, p)) * np.cos(t) - wi[2], end)
        if eta is not None:
            points += _sign_changes(lambda t: _refracted_z(wi, _normal(t, p), eta), end)
        points += [x for x in np.arctan(scale * LOBE_SCALES) if x < end]
        edges = [0.0] + sorted(points) + [end]
        return sum(integrate.quad(lost, a, b, args=(p,), epsabs=0.0, epsrel=1e-10, limit=200)[0]
                   for a, b in zip(edges[:-1], edges[1:], strict=True) if b > a)

    total = integrate.quad(inner, 0.0, np.pi, epsabs=0.0, epsrel=1e-8, limit=400,
                           points=[0.5 * np.pi])[0]
    return 2.0 * total / (np.cos(theta) * (1.0 + li))
