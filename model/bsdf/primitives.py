"""Scalar microfacet formulas, one direction or pair at a time: the one source of D, Smith
Lambda, masking G2 (with log Beta), Fresnel and the normal samplers that the compiled BSDF
kernels (kernels.py) and the random walk's next-event kernel (multiple_scattering/nee_kernel.py)
share.

The distributions, masking forms and normal samplers are named by the IntEnums of constants.py
(numba sees their members as ints: a compiled caller passes `Ndf.GGX.value`). With numba (the
gonio[fast] extra) each function is compiled on first call and cached on disk; without it they
are the same formulas as plain Python (where Python raises on a division by zero or an overflow,
numba's numpy error model gives inf or nan). The vectorised numpy versions (distributions.py,
masking.py, fresnel.py) are the models' reference path; tests/bsdf/test_bsdf_primitives.py holds
them to these."""

from __future__ import annotations

import math

import numpy as np

from model.bsdf.constants import (
    BECKMANN_CF_FROM,
    BECKMANN_CF_TERMS,
    BECKMANN_KERNEL_TAIL_FROM,
    CODY_ERFC_P,
    CODY_ERFC_Q,
    HALF_LOG_2PI,
    SQRT_PI,
    STIRLING_FROM,
    STIRLING_TERMS,
    WALTER_BASE,
    WALTER_SLOPE,
    Masking,
    Ndf,
    Sampling,
)
from model.kernel_cache import compiled

try:
    #: How every scalar formula is compiled: cached, with numpy's floating-point error model,
    #: releasing the GIL (keyed walks fill one batch from several threads).
    scalar = compiled(error_model="numpy", nogil=True)
    #: The same, inlined into each caller by numba (inline="always"): the random walk's
    #: per-event formulas, which LLVM otherwise leaves as calls (a sixth of a walk's time).
    inlined = compiled(error_model="numpy", inline="always")
    COMPILED = True
except ImportError:  # pragma: no cover - exercised only without the [fast] extra
    COMPILED = False

    def scalar(fn):
        """Without numba: the plain Python function."""
        return fn

    inlined = scalar

STIRLING_REVERSED = tuple(reversed(STIRLING_TERMS))
#: Veltkamp's constant 2^27 + 1: splits a double into two halves whose products are exact.
SPLIT = 134217729.0
#: The least normal double: Beckmann's D divides exp(-tan^2/alpha^2) by m_z^4 where both are
#: at least this (full precision), else takes -4 log m_z into the exponent.
MIN_NORMAL = 2.2250738585072014e-308


# --- geometry -----------------------------------------------------------------------------

@scalar
def unit(x, y, z):
    """(x, y, z) scaled to unit length (a zero vector stays zero)."""
    n = math.sqrt(x * x + y * y + z * z)
    if n > 0.0:
        inv = 1.0 / n  # one division instead of three, as vectors.unit does
        return x * inv, y * inv, z * inv
    return x, y, z


@scalar
def exp_square(x, sign):
    """exp(sign x^2), sign +-1, to double precision for large x: x^2's rounding error (Veltkamp
    split, exact products) is applied as a factor, instead of being amplified x^2 times by exp."""
    c = SPLIT * x
    hi = c - (c - x)
    lo = x - hi
    s = x * x
    return math.exp(sign * s) * (1.0 + sign * (((hi * hi - s) + 2.0 * hi * lo) + lo * lo))


@scalar
def erfc_continued_fraction(a):
    """t with erfc(a) = exp(-a^2) / (sqrt(pi) (a + t)), for a >= BECKMANN_CF_FROM: the
    continued fraction (1/2) / (a + 1 / (a + (3/2) / ...)) with the terms full float64 accuracy
    needs at this a (BECKMANN_CF_TERMS at a = 2, falling as 1/a^2 to 14)."""
    t = 0.0
    for k in range(min(BECKMANN_CF_TERMS, 14 + int(190.0 / (a * a))), 0, -1):
        t = 0.5 * k / (a + t)
    return t


@scalar
def cody_tail(x):
    """R = 1/sqrt(pi) - x exp(x^2) erfc(x) for x >= 4 by Cody's rational function (CODY_ERFC_P,
    CODY_ERFC_Q; constants.py), to about an ulp."""
    z = 1.0 / (x * x)
    num = CODY_ERFC_P[5] * z
    den = z
    for i in range(4):
        num = (num + CODY_ERFC_P[i]) * z
        den = (den + CODY_ERFC_Q[i]) * z
    return z * (num + CODY_ERFC_P[4]) / (den + CODY_ERFC_Q[4])


@scalar
def beckmann_a_lambda(a):
    """a * Lambda(a) of the Beckmann Smith function (distributions.beckmann_a_lambda), exp(-a^2)
    exactly rounded from a = 2 on; the closed form up to BECKMANN_KERNEL_TAIL_FROM (within ~2a^2
    ulps), then Cody's tail of erfc (cody_tail), free of cancellation:
    a Lambda = exp(-a^2) R / 2."""
    if a < BECKMANN_CF_FROM:
        return 0.5 * (math.exp(-a * a) / SQRT_PI - a * math.erfc(a))
    if a < BECKMANN_KERNEL_TAIL_FROM:
        return 0.5 * (exp_square(a, -1.0) / SQRT_PI - a * math.erfc(a))
    if not a < 27.3:  # exp(-a^2) is 0 in double (and a^2 would overflow from 1.3e154)
        return 0.0
    return 0.5 * exp_square(a, -1.0) * cody_tail(a)


@scalar
def cos_lambda(ndf, ax, ay, x, y, z):
    """|z| Lambda(x, y, z) (Distribution.cos_lambda): finite even at exactly grazing w."""
    q = (ax * x) ** 2 + (ay * y) ** 2
    c = abs(z)
    if ndf == Ndf.GGX:
        return q / (2.0 * (math.sqrt(c * c + q) + c))
    r = math.sqrt(q)
    if r == 0.0:
        return 0.0
    return r * beckmann_a_lambda(c / r)


@scalar
def normal_density(ndf, ax, ay, mx, my, mz):
    """D(m) per unit solid angle (Distribution.D), 0 for m.z <= 0."""
    if mz <= 0.0:
        return 0.0
    if ndf == Ndf.GGX:
        den = mz * mz + ((mx / ax) ** 2 + (my / ay) ** 2)
        return 1.0 / (math.pi * ax * ay * den * den)
    mz2 = mz * mz
    expo = -((mx / ax) ** 2 + (my / ay) ** 2) / mz2
    g, m4 = math.exp(expo), mz2 * mz2
    if g >= MIN_NORMAL and m4 >= MIN_NORMAL:  # 1 / mz^4 by a division (a log costs more)
        return g / (math.pi * ax * ay * m4)
    return math.exp(expo - 4.0 * math.log(mz)) / (math.pi * ax * ay)  # no subnormal between


# --- masking ------------------------------------------------------------------------------

@scalar
def stirling_correction(x):
    """log Gamma(x) - ((x - 1/2) log x - x + log sqrt(2 pi)), for x >= STIRLING_FROM."""
    r = 1.0 / x
    r2 = r * r
    s = 0.0
    for c in STIRLING_REVERSED:
        s = s * r2 + c
    return s * r


@scalar
def log_beta(p, q):
    """log B(p, q) for p, q >= 1 (masking.log_beta: the same three regions, and the same
    formulas where one argument reaches STIRLING_FROM; below, log Gamma(a) + log Gamma(b) -
    log Gamma(a + b), three libm lgamma calls at 11 ns each against 35 ns a gamma, within a few
    ulp of log Gamma(20) = 39 of it)."""
    a, b = min(p, q), max(p, q)
    s = a + b
    frac = a / s
    if b < STIRLING_FROM:
        return math.lgamma(a) + math.lgamma(b) - math.lgamma(s)
    corr_b = stirling_correction(b) - stirling_correction(s)
    if a < STIRLING_FROM:
        return math.lgamma(a) + corr_b + a - a * math.log(s) + (b - 0.5) * math.log1p(-frac)
    return (HALF_LOG_2PI - 0.5 * math.log(b) + stirling_correction(a) + corr_b
            + (a - 0.5) * math.log(frac) + b * math.log1p(-frac))


@scalar
def beta_over_cosines(ci, co, li, lo):
    """Height-correlated transmission G2 / (ci co) = B(1 + li/ci, 1 + lo/co) / (ci co): one
    division where a direction is unmasked, as at normal incidence (B(1, b) = 1/b); else B by
    three lgamma where both arguments stay below STIRLING_FROM, in log form beyond."""
    if not (ci > 0.0 and co > 0.0 and math.isfinite(li) and math.isfinite(lo)):
        return 0.0
    if li == 0.0 or lo == 0.0:  # B(1, b) = 1/b, b = 1 + l/c of the other direction
        return 1.0 / (ci * co + co * li + ci * lo)
    p, q = 1.0 + li / ci, 1.0 + lo / co
    a, b = min(p, q), max(p, q)
    if b < STIRLING_FROM:
        if a == 1.0:
            return 1.0 / (b * ci * co)
        return math.exp(math.lgamma(a) + math.lgamma(b) - math.lgamma(a + b)) / (ci * co)
    return math.exp(log_beta(p, q) - math.log(ci) - math.log(co))


@scalar
def g2_over_cosines(masking, ci, co, li, lo, transmitted):
    """G2 / (ci co) from the |cosines| and |cos| Lambdas (masking.g2_over_cosines)."""
    if masking == Masking.SEPARABLE:
        return 1.0 / ((ci + li) * (co + lo))
    if transmitted:
        return beta_over_cosines(ci, co, li, lo)
    return 1.0 / (ci * co + co * li + ci * lo)


# --- Fresnel ------------------------------------------------------------------------------

@inlined
def fresnel_e_ct(c, e, em1):
    """(F, e cos_t) at |cos_i| = c toward relative index e, em1 = e - 1 exact: fresnel_toward's
    F and the transmitted cosine times e, sqrt(e^2 - 1 + c^2), which a refraction reuses;
    (1, 0) under total internal reflection."""
    e_ct2 = em1 * (e + 1.0) + c * c
    if e_ct2 <= 0.0:
        return 1.0, 0.0
    e_ct = math.sqrt(e_ct2)
    den_s = c + e_ct
    den_p = e * e * c + e_ct
    if den_s <= 0.0 or den_p <= 0.0:
        return 1.0, e_ct
    e2m1 = em1 * (e + 1.0)
    rs = -e2m1 / (den_s * den_s)
    rp = e2m1 * (c * c * (e * e + 1.0) - 1.0) / (den_p * den_p)
    return 0.5 * (rs * rs + rp * rp), e_ct


@scalar
def fresnel_toward(c, e, em1):
    """F at |cos_i| = c toward relative index e, em1 = e - 1 exact
    (fresnel.reflectance_transmittance_toward's F); 1 under total internal reflection."""
    return fresnel_e_ct(c, e, em1)[0]


@scalar
def transmittance_e(c, e_ct, e):
    """1 - F from c = |cos_i| and e cos_t, without a subtraction (fresnel._transmittance)."""
    den_s = c + e_ct
    den_p = e * e * c + e_ct
    if den_s <= 0.0 or den_p <= 0.0:
        return 0.0
    return 2.0 * ((c / den_s) * (e_ct / den_s) + e * e * (c / den_p) * (e_ct / den_p))


@scalar
def dielectric_transmittance(c, ct, e):
    """1 - F from both |cosines| (fresnel.dielectric_transmittance)."""
    return transmittance_e(c, e * ct, e)


@scalar
def conductor_fresnel(c, has_f, n_c):
    """fresnel.fresnel_conductor for one cosine and complex index n_c; 1 without an index
    (has_f False: a perfect mirror)."""
    if not has_f:
        return 1.0
    rs, rp = fresnel_amplitudes(c, n_c, (n_c - 1.0) * (n_c + 1.0))
    return 0.5 * (abs(rs) ** 2 + abs(rp) ** 2)


@scalar
def fresnel_amplitudes(c, n, n2m1):
    """fresnel.fresnel_amplitudes for one cosine c >= 0: complex (r_s, r_p) toward the
    complex index n, n2m1 = n^2 - 1 exact; (-1, -1) where both denominators vanish."""
    root = np.sqrt(n2m1 + c * c)  # principal branch, as numpy's in fresnel_amplitudes
    n2 = n * n
    den_s = c + root
    den_p = n2 * c + root
    if den_s == 0 or den_p == 0:
        return complex(-1.0, 0.0), complex(-1.0, 0.0)
    if n2m1 == 0:
        return complex(0.0, 0.0), complex(0.0, 0.0)
    return -n2m1 / den_s / den_s, n2m1 * ((n2 + 1.0) * c * c - 1.0) / den_p / den_p


# --- normal sampling ----------------------------------------------------------------------

@scalar
def walter_scale(cos_i):
    """Walter's roughness scale for sampling (microfacet.walter_widening)."""
    return WALTER_BASE - WALTER_SLOPE * math.sqrt(abs(cos_i))


@scalar
def unit_slope_radius(ndf, u):
    """Slope radius of a unit-roughness normal drawn from D m.z with uniform u
    (Distribution._unit_slope_radius)."""
    if ndf == Ndf.GGX:
        return math.sqrt(u / (1.0 - u))
    return math.sqrt(-math.log1p(-u))


#: fdlibm's minimax coefficients of sin t (t^3 to t^13) and cos t (t^4 to t^14) on |t| <= pi/4
#: (k_sin.c, k_cos.c: below an ulp there).
SIN_1, SIN_2, SIN_3, SIN_4, SIN_5, SIN_6 = (
    -1.66666666666666324348e-01, 8.33333333332248946124e-03, -1.98412698298579493134e-04,
    2.75573137070700676789e-06, -2.50507602534068634195e-08, 1.58969099521155010221e-10)
COS_1, COS_2, COS_3, COS_4, COS_5, COS_6 = (
    4.16666666666666019037e-02, -1.38888888888741095749e-03, 2.48015872894767294178e-05,
    -2.75573143513906633035e-07, 2.08757232129817482790e-09, -1.13596475577881948265e-11)


@inlined
def cos_sin_2pi(u):
    """(cos 2 pi u, sin 2 pi u) for 0 <= u <= 1 by quadrant and fdlibm's kernels, split in
    halves (Estrin) so that the chain of dependent operations is short: within an ulp or two
    of libm's, branch-free so that it vectorises, and in a scalar loop a fraction of libm's
    cos and sin (20 ns a pair)."""
    q = math.floor(4.0 * u + 0.5)
    t = (2.0 * math.pi) * (u - 0.25 * q)  # exact difference, |t| <= pi / 4
    z = t * t
    w = z * z
    r = SIN_2 + z * (SIN_3 + z * SIN_4) + z * w * (SIN_5 + z * SIN_6)
    s = t + z * t * (SIN_1 + z * r)
    r = z * (COS_1 + z * (COS_2 + z * COS_3)) + w * w * (COS_4 + z * (COS_5 + z * COS_6))
    half = 0.5 * z
    one_minus = 1.0 - half
    c = one_minus + (((1.0 - one_minus) - half) + z * r)
    quadrant = q - 4.0 * math.floor(0.25 * q)
    odd = (quadrant == 1.0) | (quadrant == 3.0)
    cq, sq = (s, c) if odd else (c, s)
    return (-cq if (quadrant == 1.0) | (quadrant == 2.0) else cq,
            -sq if (quadrant == 2.0) | (quadrant == 3.0) else sq)


@inlined
def ggx_visible_normal(ax, ay, ix, iy, iz, u1, u2):
    """GGX visible normal for wi (iz >= 0) from uniforms u1, u2 (Heitz 2018;
    GGX.sample_visible)."""
    vx, vy, vz = ax * ix, ay * iy, iz
    n = math.sqrt(vx * vx + vy * vy + vz * vz)
    vx, vy, vz = vx / n, vy / n, vz / n
    lensq = vx * vx + vy * vy
    if lensq > 0.0:
        inv = 1.0 / math.sqrt(lensq)
        t1x, t1y = -vy * inv, vx * inv
    else:
        t1x, t1y = 1.0, 0.0
    t2x, t2y, t2z = -vz * t1y, vz * t1x, vx * t1y - vy * t1x  # vh x t1, t1z = 0
    r = math.sqrt(u1)
    cos_p, sin_p = cos_sin_2pi(u2)
    p1 = r * cos_p
    p2 = r * sin_p
    s = 0.5 * (1.0 + vz)
    p2 = (1.0 - s) * math.sqrt(max(1.0 - p1 * p1, 0.0)) + s * p2
    p3 = math.sqrt(max(1.0 - p1 * p1 - p2 * p2, 0.0))
    nx = p1 * t1x + p2 * t2x + p3 * vx
    ny = p1 * t1y + p2 * t2y + p3 * vy
    nz = p2 * t2z + p3 * vz
    ex, ey, ez = ax * nx, ay * ny, max(nz, 0.0)
    n = math.sqrt(ex * ex + ey * ey + ez * ez)
    return ex / n, ey / n, ez / n


@scalar
def walter_normal(ndf, ax, ay, iz, u1, u2):
    """Normal drawn from D m.z at Walter's widened roughness for cos_i = iz
    (Distribution.sample_normal on the scaled alpha)."""
    phi = 2.0 * math.pi * u2
    k = walter_scale(iz)
    r = unit_slope_radius(ndf, u1)
    sx = ax * k * r * math.cos(phi)
    sy = ay * k * r * math.sin(phi)
    inv = 1.0 / math.sqrt(1.0 + sx * sx + sy * sy)
    return -sx * inv, -sy * inv, inv


@scalar
def sample_normal(ndf, ax, ay, sampling, ix, iy, iz, u1, u2):
    """Normal for wi (iz >= 0) by the sampling scheme: visible normals (GGX only: Beckmann's
    inversion needs erfinv, which numba lacks), or Walter's for either distribution."""
    if sampling == Sampling.WALTER:
        return walter_normal(ndf, ax, ay, iz, u1, u2)
    return ggx_visible_normal(ax, ay, ix, iy, iz, u1, u2)


@scalar
def normal_pdf(ndf, ax, ay, sampling, ix, iy, iz, mx, my, mz):
    """Density of the normal m sample_normal draws for wi (iz >= 0): the visible-normal
    density, or Walter's widened D m.z (MicrofacetModel._normal_pdf)."""
    if sampling == Sampling.VISIBLE:
        wm = ix * mx + iy * my + iz * mz
        den = iz + cos_lambda(ndf, ax, ay, ix, iy, iz)
        if wm <= 0.0 or den <= 0.0:
            return 0.0
        return wm * normal_density(ndf, ax, ay, mx, my, mz) / den
    k = walter_scale(iz)
    return normal_density(ndf, ax * k, ay * k, mx, my, mz) * max(mz, 0.0)
