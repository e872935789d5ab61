"""Compiled visible-normal sampling from any direction on the sphere (the walk kernel's sampler).

GGX is Heitz 2018's warp (primitives.ggx_visible_normal, which holds below the horizon too);
Beckmann is beckmann_sphere's log-CDF inversion, one direction at a time, with the two special
functions numba lacks: erfcx (direct form, then primitives.erfc_continued_fraction) and the
normal quantile ndtri (Acklam's rational approximation refined by one Halley step to full double
precision). beckmann_sphere (numpy, scipy) is the
reference.
"""

from __future__ import annotations

import math

from sim.bsdf.constants import BECKMANN_CF_FROM, SQRT_PI, Ndf
from sim.bsdf.primitives import erfc_continued_fraction, ggx_visible_normal, scalar, unit

LOG_2 = math.log(2.0)
#: Steps of the Beckmann slope inversion at most (it converges in a few).
NEWTON_STEPS = 60
# Acklam's coefficients: central numerator, central denominator, tail numerator and denominator
_A = (-3.969683028665376e+01, 2.209460984245205e+02, -2.759285104469687e+02,
      1.383577518672690e+02, -3.066479806614716e+01, 2.506628277459239e+00)
_B = (-5.447609879822406e+01, 1.615858368580409e+02, -1.556989798598866e+02,
      6.680131188771972e+01, -1.328068155288572e+01)
_C = (-7.784894002430293e-03, -3.223964580411365e-01, -2.400758277161838e+00,
      -2.549732539343734e+00, 4.374664141464968e+00, 2.938163982698783e+00)
_D = (7.784695709041462e-03, 3.224671290700398e-01, 2.445134137142996e+00,
      3.754408661907416e+00)
_LOW = 0.02425


@scalar
def erfcx(x):
    """exp(x^2) erfc(x) for x >= 0."""
    if x < BECKMANN_CF_FROM:
        return math.exp(x * x) * math.erfc(x)
    return 1.0 / (SQRT_PI * (x + erfc_continued_fraction(x)))


@scalar
def _lower_quantile(p):
    """Standard normal quantile for 0 < p <= 1/2."""
    if p < _LOW:
        q = math.sqrt(-2.0 * math.log(p))
        x = ((((((_C[0] * q + _C[1]) * q + _C[2]) * q + _C[3]) * q + _C[4]) * q + _C[5])
             / ((((_D[0] * q + _D[1]) * q + _D[2]) * q + _D[3]) * q + 1.0))
    else:
        q = p - 0.5
        r = q * q
        x = ((((((_A[0] * r + _A[1]) * r + _A[2]) * r + _A[3]) * r + _A[4]) * r + _A[5]) * q
             / (((((_B[0] * r + _B[1]) * r + _B[2]) * r + _B[3]) * r + _B[4]) * r + 1.0))
    e = 0.5 * math.erfc(-x / math.sqrt(2.0)) - p
    u = e * math.sqrt(2.0 * math.pi) * math.exp(0.5 * x * x)
    return x - u / (1.0 + 0.5 * x * u)


@scalar
def ndtri(p):
    """Standard normal quantile Phi^-1(p) for 0 < p < 1, from the nearer tail."""
    if p > 0.5:
        return -_lower_quantile(1.0 - p)
    return _lower_quantile(p)


@scalar
def _log_cdf(x, mu):
    """(log F(x), F'(x) / F(x)), F(x) = int_{-inf}^x (mu - t) exp(-t^2)/sqrt(pi) dt (x <= mu;
    beckmann_sphere._log_cdf), both from one erfc, stable in the tails."""
    if x <= 0.0:
        q = mu * erfcx(-x) + 1.0 / SQRT_PI  # F = exp(-x^2) q / 2
        return -x * x + math.log(q) - LOG_2, 2.0 * (mu - x) / (SQRT_PI * q)
    e = math.exp(-x * x)
    q = mu * math.erfc(-x) + e / SQRT_PI  # F = q / 2
    return math.log(q) - LOG_2, 2.0 * (mu - x) * e / (SQRT_PI * q)


@scalar
def _visible_slope(mu, u):
    """Slope x < mu of density proportional to (mu - x) exp(-x^2), by Halley's method on
    log F (beckmann_sphere._visible_slope takes Newton steps), started left of the root; a
    step that would leave [bracket, mu) is a Newton step, which from the left stays there."""
    target = math.log(u) + _log_cdf(mu, mu)[0]
    bound = math.log(0.5 * (max(mu, 0.0) + 1.0 / SQRT_PI)) - target
    x = min(-math.sqrt(max(bound, 0.0)), mu)
    for _ in range(NEWTON_STEPS):
        g, d1 = _log_cdf(x, mu)  # log F and (log F)' = f / F
        gap = mu - x
        if gap <= 0.0:
            break
        d2 = d1 * (-1.0 / gap - 2.0 * x) - d1 * d1  # (log F)''
        r = target - g
        step = 2.0 * r * d1 / (2.0 * d1 * d1 + r * d2)
        if not (math.isfinite(step) and 0.0 < step < gap):
            step = r / d1
        if not (math.isfinite(step) and step > 0.0):
            break
        x = min(x + step, mu)
        if step <= 1e-6 * (1.0 + abs(x)):  # Halley: the error left is of order step^3
            break
    return x


@scalar
def beckmann_visible_unit(vx, vy, vz, u1, u2):
    """Visible normal of the alpha = 1 Beckmann surface seen from unit v, any direction
    (beckmann_sphere.beckmann_visible_unit)."""
    sin_t = math.sqrt(vx * vx + vy * vy)
    if sin_t > 0.0:
        mu = min(max(vz / max(sin_t, 1e-200), -1e4), 1e8)
        c, s = vx / sin_t, vy / sin_t
    else:
        mu = 1e8 if vz > 0.0 else -1e4
        c, s = 1.0, 0.0
    x = _visible_slope(mu, min(max(u1, 1e-300), 1.0 - 2.0**-53))
    y = ndtri(min(max(u2, 2.0**-60), 1.0 - 2.0**-53)) / math.sqrt(2.0)
    return unit(-(c * x - s * y), -(s * x + c * y), 1.0)


@scalar
def visible_normal(ndf, ax, ay, x, y, z, u1, u2):
    """m ~ D_visible((x, y, z), .) for a direction anywhere on the sphere
    (Distribution.sample_visible_sphere)."""
    if ndf == Ndf.GGX:
        return ggx_visible_normal(ax, ay, x, y, z, u1, u2)
    vx, vy, vz = unit(ax * x, ay * y, z)
    nx, ny, nz = beckmann_visible_unit(vx, vy, vz, u1, u2)
    return unit(ax * nx, ay * ny, max(nz, 0.0))
