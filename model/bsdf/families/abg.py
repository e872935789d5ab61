"""ABg: the Harvey-Shack-type scatter model of optical-design programs (Zemax OpticStudio,
FRED, ASAP), reflection side, with OpticStudio's definitions ("Available Scatter Models"):

    BSDF = A / (B + |x|^g),   x = beta - beta0,

beta the projection of the scattered direction on the surface plane (|beta| = sin theta_s),
beta0 that of the specular direction (|beta0| = sin theta_r). Restrictions, as OpticStudio's:
A >= 0; B > 1e-12 unless g = 0 (then B may be 0); g = 0 is a constant BSDF. OpticStudio takes
any g ("typically between 0 and 3"); here |g| <= 10, where |x|^g stays finite in float64.
Reciprocal: with wi toward the source, beta0 = -wi_xy and |x| = |wo_xy + wi_xy|.

Its total integrated scatter is A times the integral of 1 / (B + |x|^g) over the unit disk of
beta (d^2 beta = cos theta_s d omega), whose radial part has the closed form radial_integral.
sample() draws |x| from annuli about beta0 that carry the radial integral's exact mass, uniform
in area within each, with a uniform azimuth; a beta outside the unit disk is a failed sample."""

from __future__ import annotations

import math

import numpy as np

from model.bsdf.families.base import Parameter, ReflectionFamily, reach_in_unit_disk

A = Parameter("A", 0.0, math.inf, True, "BSDF scale, 1/sr")
B = Parameter("B", 0.0, math.inf, True, "roll-off knee: BSDF = A / B at the specular direction")
G = Parameter("g", -10.0, 10.0, False, "slope of log BSDF against log |x| beyond the knee")
#: OpticStudio's smallest B when g != 0.
B_MIN = 1e-12
#: The sampler's annuli about beta0: geometric radii from the knee / 1e3 (within [1e-9, 1e-3])
#: to the largest |x|, 2.
ANNULI = 256
X_MAX = 2.0
#: hyp_one: Pfaff's series alone from this c on (|g| below 1/6), to HYP_TERMS terms (the
#: last below 1e-19 there); HYP_NEAR_TERMS terms of the series within x <= 2 and of the tail.
HYP_LARGE_C = 12.0
HYP_TERMS = 200
HYP_NEAR_TERMS = 100
#: Azimuths of the trapezoid rule of the oblique total integrated scatter (periodic, smooth).
TIS_AZIMUTHS = 512


def pfaff_series(c: float, x: np.ndarray, terms: int) -> np.ndarray:
    """2F1(1, c; 1 + c; -x) by Pfaff's transformation, 2F1(1, 1; 1 + c; w) / (1 + x) with
    w = x / (1 + x), summed to `terms` terms (each at most w^n, and Gamma(1 + c) / n^c)."""
    w = x / (1.0 + x)
    term = np.ones_like(x)
    total = np.ones_like(x)
    for n in range(1, terms + 1):
        term = term * n * w / (c + n)
        total = total + term
    return total / (1.0 + x)


def hyp_one(c: float, z: np.ndarray) -> np.ndarray:
    """Gauss's 2F1(1, c; 1 + c; z) = c int_0^1 t^(c-1) / (1 - z t) dt for z <= 0 and c > 0,
    within 3e-14 of mpmath for c from 0.2 to 1e300 (near-integer c included) and -z to 1e15.

    With x = -z: for c >= HYP_LARGE_C, Pfaff's series (HYP_TERMS terms); otherwise Pfaff's
    series up to x = 2 (w <= 2/3, HYP_NEAR_TERMS terms) and beyond it c x^-c J(x), where
    J(x) = int_0^x s^(c-1) / (1 + s) ds = J(2) + sum_k (-1)^k (2^-e - x^-e) / e, e = k + 1 - c
    (the integral from 2 to x in v = 1/s, its geometric series in v <= 1/2), each term
    written with expm1 so that e near 0 (integer c) loses nothing (log(x / 2) at e = 0).
    scipy's hyp2f1 fails here for large c and near integer c at large x."""
    x = -np.asarray(z, dtype=np.float64)
    if c >= HYP_LARGE_C:
        return pfaff_series(c, x, HYP_TERMS)
    near = x <= 2.0
    inner = pfaff_series(c, np.where(near, x, 2.0), HYP_NEAR_TERMS)
    if near.all():
        return inner
    x_far = np.where(near, 4.0, x)
    ratio = np.log(0.5 * x_far)
    tail = np.zeros_like(x_far)
    for k in range(HYP_NEAR_TERMS + math.ceil(c)):
        e = k + 1.0 - c
        if e > 0:
            part = 2.0**-e * -np.expm1(-e * ratio) / e
        elif e < 0:
            part = np.exp(-e * np.log(x_far)) * np.expm1(e * ratio) / e
        else:
            part = ratio
        tail = tail + (-1.0) ** k * part
    far = c * np.exp(-c * np.log(x_far)) * (2.0**c / c * inner + tail)
    return np.where(near, inner, far)


def radial_integral(r: np.ndarray, b: float, g: float) -> np.ndarray:
    """int_0^r s / (b + s^g) ds in closed form (hyp_one: Gauss's hypergeometric function):
    g = 0: r^2 / (2 (b + 1)); g > 0: r^2 / (2 b) 2F1(1, 2/g; 1 + 2/g; -r^g / b), which is
    log(1 + r^2 / b) / 2 at g = 2; g < 0, h = -g: r^(2+h) / (2+h) 2F1(1, (2+h)/h; 1 + (2+h)/h;
    -b r^h)."""
    r = np.asarray(r, dtype=np.float64)
    if g == 0.0:
        return r * r / (2.0 * (b + 1.0))
    if g > 0.0:
        return r * r / (2.0 * b) * hyp_one(2.0 / g, -(r**g) / b)
    h = -g
    return r ** (2.0 + h) / (2.0 + h) * hyp_one((2.0 + h) / h, -b * r**h)


class ABg(ReflectionFamily):
    """ABg scatter A / (B + |beta - beta0|^g) in reflection, the `abg` family."""

    family = "abg"
    PARAMETERS = (A, B, G)

    def __init__(self, A: float = 1e-3, B: float = 1e-3, g: float = 2.0):
        super().__init__(A=A, B=B, g=g)
        if self.g != 0.0 and self.B <= B_MIN:
            raise ValueError(f"B must be > {B_MIN} unless g = 0, got B={B!r} with g={g!r}")
        # the knee B^(1/g), in logs (it over- or underflows for small g)
        log_knee = math.log(self.B) / self.g if self.g > 0 else 0.0
        inner = math.exp(min(max(log_knee + math.log(1e-3), math.log(1e-9)), math.log(1e-3)))
        self.radii = np.concatenate([[0.0], np.geomspace(inner, X_MAX, ANNULI)])
        mass = np.diff(radial_integral(self.radii, self.B, self.g))
        self.cumulative = np.concatenate([[0.0], np.cumsum(mass)]) / mass.sum()
        self.density = (mass / mass.sum()) / (math.pi * np.diff(self.radii**2))

    def separation(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        """|x| = |beta - beta0| = |wo_xy + wi_xy| for unit directions above the surface."""
        return np.hypot(wo[..., 0] + wi[..., 0], wo[..., 1] + wi[..., 1])

    def _eval(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        # g < 0 at x = 0, or |x|^g past the float range for g near -10: |x|^g = inf, f = 0
        with np.errstate(divide="ignore", over="ignore"):
            return self.A / (self.B + self.separation(wi, wo) ** self.g)

    def _pdf(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        x = self.separation(wi, wo)
        k = np.clip(np.searchsorted(self.radii, x, side="right") - 1, 0, ANNULI - 1)
        return np.where(x < X_MAX, self.density[k], 0.0) * wo[:, 2]

    def _sample_directions(self, wi: np.ndarray, u: np.ndarray) -> np.ndarray:
        k = np.clip(np.searchsorted(self.cumulative, u[:, 0], side="right") - 1, 0, ANNULI - 1)
        lo, hi = self.cumulative[k], self.cumulative[k + 1]
        t = np.clip((u[:, 0] - lo) / np.where(hi > lo, hi - lo, 1.0), 0.0, 1.0)
        r0, r1 = self.radii[k], self.radii[k + 1]
        x = np.sqrt(r0 * r0 + (r1 * r1 - r0 * r0) * t)
        phi = 2.0 * math.pi * u[:, 1]
        bx, by = x * np.cos(phi) - wi[:, 0], x * np.sin(phi) - wi[:, 1]
        z2 = 1.0 - bx * bx - by * by
        inside = z2 > 0
        return np.where(inside[:, None],
                        np.stack([bx, by, np.sqrt(np.where(inside, z2, 0.0))], axis=-1), 0.0)

    def total_integrated_scatter(self, wi) -> np.ndarray:
        """Directional albedo int f cos dw over the hemisphere for incident directions wi
        (..., 3): 2 pi A I(1) at normal incidence (I = radial_integral), else A times the
        integral over azimuths about beta0 of I(distance to the unit circle), by the trapezoid
        rule on TIS_AZIMUTHS points (a smooth periodic integrand). 0 below the horizon."""
        wi = np.asarray(wi, dtype=np.float64)
        wi = wi / np.linalg.norm(wi, axis=-1, keepdims=True)
        b0 = -wi[..., :2]
        phi = 2.0 * math.pi * np.arange(TIS_AZIMUTHS) / TIS_AZIMUTHS
        e = np.stack([np.cos(phi), np.sin(phi)], axis=-1)
        reach = reach_in_unit_disk(b0[..., None, :], e)
        tis = self.A * 2.0 * math.pi * np.mean(radial_integral(reach, self.B, self.g), axis=-1)
        return np.where(wi[..., 2] > 0, tis, 0.0)
