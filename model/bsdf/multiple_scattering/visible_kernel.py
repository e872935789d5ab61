"""Compiled visible-normal sampling from any direction on the sphere (the walk kernel's sampler).

GGX is Heitz 2018's warp (primitives.ggx_visible_normal, which holds below the horizon too);
Beckmann is beckmann_sphere's log-CDF inversion, one direction at a time, with the two special
functions numba lacks: erfcx (libm's erfc times an exactly rounded exp(x^2), the continued
fraction only beyond x = 25) and the
normal quantile ndtri (Wichura's AS241, rational functions good to double precision, so no
erfc is spent on the second slope). The inversion starts from a table of converged slopes
(bilinear in the polar angle and u), which halves its steps. beckmann_sphere (numpy, scipy) is
the reference and builds that table.
"""

from __future__ import annotations

import math

import numpy as np

from model.bsdf import beckmann_sphere
from model.bsdf.constants import BECKMANN_CF_FROM, SQRT_PI, Ndf
from model.bsdf.primitives import (
    cos_sin_2pi,
    erfc_continued_fraction,
    exp_square,
    ggx_visible_normal,
    inlined,
    scalar,
    unit,
)

LOG_2 = math.log(2.0)
#: Steps of the Beckmann slope inversion at most (it converges in a few).
NEWTON_STEPS = 60
#: erfcx switches to the continued fraction here (erfc(25) = 8e-274 is still a normal number).
ERFCX_CF_FROM = 25.0
#: The start table: polar angles 0..START_THETA_MAX (beyond it, 162-180 deg, the slopes run off
#: towards mu = cot theta and the bound-based start is kept) by u = 0..1; in its first u cell and
#: its last two (the tails) the bound-based start is kept too.
START_THETAS, START_US, START_THETA_MAX = 33, 65, 0.9 * math.pi


def _start_table():
    """Converged slopes x(theta, u) at the table's nodes (beckmann_sphere's inversion)."""
    theta = np.linspace(0.0, START_THETA_MAX, START_THETAS)[:, None]
    u = np.linspace(0.0, 1.0, START_US)[None, :]
    mu = np.where(theta > 0.0, np.cos(theta) / np.maximum(np.sin(theta), 1e-300), 1e8)
    mu, u = np.broadcast_arrays(np.clip(mu, -1e4, 1e8), np.clip(u, 1e-300, 1.0 - 2.0**-53))
    return beckmann_sphere._visible_slope(mu.ravel(), u.ravel()).reshape(mu.shape)


START = _start_table()
THETA_SCALE = (START_THETAS - 1) / START_THETA_MAX
# Wichura's AS241 (PPND16): numerator and denominator coefficients, lowest power first, of the
# central region |p - 1/2| <= 0.425, the near tail r = sqrt(-log p) <= 5 and the far tail
_A = (3.3871328727963666080e+0, 1.3314166789178437745e+2, 1.9715909503065514427e+3,
      1.3731693765509461125e+4, 4.5921953931549871457e+4, 6.7265770927008700853e+4,
      3.3430575583588128105e+4, 2.5090809287301226727e+3)
_B = (1.0, 4.2313330701600911252e+1, 6.8718700749205790830e+2, 5.3941960214247511077e+3,
      2.1213794301586595867e+4, 3.9307895800092710610e+4, 2.8729085735721942674e+4,
      5.2264952788528545610e+3)
_C = (1.42343711074968357734e+0, 4.63033784615654529590e+0, 5.76949722146069140550e+0,
      3.64784832476320460504e+0, 1.27045825245236838258e+0, 2.41780725177450611770e-1,
      2.27238449892691845833e-2, 7.74545014278341407640e-4)
_D = (1.0, 2.05319162663775882187e+0, 1.67638483018380384940e+0, 6.89767334985100004550e-1,
      1.48103976427480074590e-1, 1.51986665636164571966e-2, 5.47593808499534494600e-4,
      1.05075007164441684324e-9)
_E = (6.65790464350110377720e+0, 5.46378491116411436990e+0, 1.78482653991729133580e+0,
      2.96560571828504891230e-1, 2.65321895265761230930e-2, 1.24266094738807843860e-3,
      2.71155556874348757815e-5, 2.01033439929228813265e-7)
_F = (1.0, 5.99832206555887937690e-1, 1.36929880922735805310e-1, 1.48753612908506148525e-2,
      7.86869131145613259100e-4, 1.84631831751005468180e-5, 1.42151175831644588870e-7,
      2.04426310338993978564e-15)


@scalar
def _ratio(num, den, r):
    """num(r) / den(r), two degree-7 polynomials by Horner's rule."""
    p, q = num[7], den[7]
    for k in range(6, -1, -1):
        p = p * r + num[k]
        q = q * r + den[k]
    return p / q


@scalar
def erfcx(x):
    """exp(x^2) erfc(x) for x >= 0: by libm's erfc below ERFCX_CF_FROM (the continued fraction
    needs up to 60 chained divisions near x = 2, which made Beckmann's slope inversion from
    below the horizon 6x slower), then primitives.erfc_continued_fraction (14 terms there)."""
    if x < BECKMANN_CF_FROM:
        return math.exp(x * x) * math.erfc(x)
    if x < ERFCX_CF_FROM:
        return exp_square(x, 1.0) * math.erfc(x)
    return 1.0 / (SQRT_PI * (x + erfc_continued_fraction(x)))


@scalar
def ndtri(p):
    """Standard normal quantile Phi^-1(p) for 0 < p < 1 (AS241: about 1e-16 relative, no
    special function)."""
    q = p - 0.5
    if abs(q) <= 0.425:
        return q * _ratio(_A, _B, 0.180625 - q * q)
    r = math.sqrt(-math.log(p if q < 0.0 else 1.0 - p))
    x = _ratio(_C, _D, r - 1.6) if r <= 5.0 else _ratio(_E, _F, r - 5.0)
    return -x if q < 0.0 else x


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
def _start(mu, u, theta, target):
    """Where the slope inversion starts: the table's bilinear value inside it (median 3e-4 from
    the root, up to 0.04 near theta = 0.9 pi; either side), else the bound
    F(x) <= exp(-x^2)(max(mu, 0) + 1/sqrt(pi))/2, left of the root."""
    t = theta * THETA_SCALE
    j = u * (START_US - 1)
    i, k = int(t), int(j)
    if i < START_THETAS - 1 and 1 <= k < START_US - 3:
        ft, fu = t - i, j - k
        x = ((1.0 - ft) * ((1.0 - fu) * START[i, k] + fu * START[i, k + 1])
             + ft * ((1.0 - fu) * START[i + 1, k] + fu * START[i + 1, k + 1]))
        if x < mu:
            return x
    bound = math.log(0.5 * (max(mu, 0.0) + 1.0 / SQRT_PI)) - target
    return min(-math.sqrt(max(bound, 0.0)), mu)


@scalar
def _visible_slope(mu, u, theta):
    """Slope x < mu of density proportional to (mu - x) exp(-x^2) (theta = acot mu), by
    Halley's method on log F (beckmann_sphere._visible_slope takes Newton steps) from _start; a
    step that would leave (-inf, mu) or go against the residual is a Newton step, which from
    either side lands left of the root (log F is concave) and from the left stays there."""
    target = math.log(u) + _log_cdf(mu, mu)[0]
    x = _start(mu, u, theta, target)
    previous = 0.0
    for _ in range(NEWTON_STEPS):
        g, d1 = _log_cdf(x, mu)  # log F and (log F)' = f / F
        gap = mu - x
        if gap <= 0.0:
            break
        d2 = d1 * (-1.0 / gap - 2.0 * x) - d1 * d1  # (log F)''
        r = target - g
        step = 2.0 * r * d1 / (2.0 * d1 * d1 + r * d2)
        if not (math.isfinite(step) and step < gap and step * r > 0.0):
            step = r / d1
        if not (math.isfinite(step) and step != 0.0):
            break
        if step * previous < 0.0 and abs(step) >= 0.5 * abs(previous):
            break  # a 2-cycle in log F's rounding noise: x is at rounding already
        previous = step
        x = min(x + step, mu)
        # small against x and against the root's scale near it (the density's width F/f, its
        # distance to mu where it vanishes): Halley leaves an error of order the step's cube; the
        # bound against x alone stopped 0.7 % of a width short where mu << -1
        if abs(step) <= 1e-6 * min(1.0 + abs(x), 1.0 / max(d1, 1.0 / gap)):
            break
    return x


@scalar
def beckmann_visible_unit(vx, vy, vz, u1, u2):
    """Visible normal of the alpha = 1 Beckmann surface seen from unit v, any direction
    (beckmann_sphere.beckmann_visible_unit); from straight above in closed form, as there."""
    sin_t = math.sqrt(vx * vx + vy * vy)
    if sin_t > 0.0:
        mu = min(max(vz / max(sin_t, 1e-200), -1e4), 1e8)
        c, s = vx / sin_t, vy / sin_t
    elif vz > 0.0:  # beckmann_sphere.vertical_slopes
        u1 = min(max(u1, 0.0), 1.0 - 2.0**-53)
        r = math.sqrt(-math.log1p(-u1))
        cos_p, sin_p = cos_sin_2pi(u2)
        return unit(-r * cos_p, -r * sin_p, 1.0)
    else:
        mu = 1e8 if vz > 0.0 else -1e4
        c, s = 1.0, 0.0
    x = _visible_slope(mu, min(max(u1, 1e-300), 1.0 - 2.0**-53), math.atan2(sin_t, vz))
    y = ndtri(min(max(u2, 2.0**-60), 1.0 - 2.0**-53)) / math.sqrt(2.0)
    return unit(-(c * x - s * y), -(s * x + c * y), 1.0)


@inlined
def visible_normal(s, x, y, z, u1, u2):
    """m ~ D_visible((x, y, z), .) on the slopes of the Surface s, for a direction anywhere on
    the sphere (Distribution.sample_visible_sphere)."""
    ax, ay = s.alpha_x, s.alpha_y
    if s.ndf == Ndf.GGX:
        return ggx_visible_normal(ax, ay, x, y, z, u1, u2)
    vx, vy, vz = unit(ax * x, ay * y, z)
    nx, ny, nz = beckmann_visible_unit(vx, vy, vz, u1, u2)
    return unit(ax * nx, ay * ny, max(nz, 0.0))
