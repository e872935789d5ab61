"""Exact Fresnel reflectance, dielectric (with total internal reflection) and conductor, and the
complex s/p amplitudes behind it (for the Mueller matrices).

Written without cancellation so that the transmittance 1 - F stays accurate near grazing and
near the critical angle, and the relative index may be 1 +- 1e-12."""

from __future__ import annotations

import numpy as np


def dielectric_reflectance_transmittance(
    cos_i: np.ndarray, eta: np.ndarray | float
) -> tuple[np.ndarray, np.ndarray]:
    """(F, 1 - F) for light meeting an interface of relative index eta = n_interior / n_exterior.

    cos_i is the cosine to the interface normal that points into the exterior; negative
    cos_i means the light arrives from the interior (the index ratio is then 1/eta).
    Both values are computed directly (no 1 - F subtraction); TIR gives (1, 0).
    """
    cos_i = np.asarray(cos_i, dtype=np.float64)
    eta = np.asarray(eta, dtype=np.float64)
    inside = cos_i < 0
    e = np.where(inside, 1.0 / eta, eta)
    return reflectance_transmittance_toward(np.abs(cos_i), e, np.where(inside, (1 - eta) / eta,
                                                                       eta - 1))


def reflectance_transmittance_toward(
    c: np.ndarray, e: np.ndarray, e_minus_1: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(F, 1 - F) for |cos_i| = c toward a medium of relative index e (e_minus_1 = e - 1, exact).

    The amplitude numerators are written with e^2 - 1 = (e - 1)(e + 1), so F keeps full
    relative accuracy when e = 1 +- 1e-12 (F ~ 1e-25), given an exact e - 1.
    """
    # (e cos_t)^2 = e^2 - sin_i^2 = (e - 1)(e + 1) + c^2: no 1 - c^2 rounding to 1 at grazing
    # (which would make a matched interface, e = 1, reflect everything below c ~ 1e-8)
    e_ct2 = e_minus_1 * (e + 1.0) + c * c
    tir = e_ct2 <= 0
    e_ct = np.sqrt(np.where(tir, 0.0, e_ct2))
    e2m1 = e_minus_1 * (e + 1.0)
    den_s = c + e_ct
    den_p = e * e * c + e_ct
    ok = ~tir & (den_s > 0) & (den_p > 0)
    den_s = np.where(ok, den_s, 1.0)
    den_p = np.where(ok, den_p, 1.0)
    rs = -e2m1 / (den_s * den_s)  # (c - e cos_t) / (c + e cos_t)
    rp = e2m1 * (c * c * (e * e + 1.0) - 1.0) / (den_p * den_p)
    f = np.where(ok, 0.5 * (rs * rs + rp * rp), 1.0)
    return f, np.where(ok, _transmittance(c, e_ct, e, den_s, den_p), 0.0)


def dielectric_transmittance(cos_i: np.ndarray, cos_t: np.ndarray, e: np.ndarray) -> np.ndarray:
    """1 - F from both |cosines| when the refracted one is already known (transmission lobe).

    e = n_t / n_i. Taking cos_t as given avoids the cancellation of sqrt(e^2 - sin_i^2) near
    the critical angle, so f_t(i, o) and f_t(o, i) are equally accurate.
    """
    e_ct = e * cos_t
    den_s = cos_i + e_ct
    den_p = e * e * cos_i + e_ct
    ok = (den_s > 0) & (den_p > 0)
    return np.where(ok, _transmittance(cos_i, e_ct, e, np.where(ok, den_s, 1.0),
                                       np.where(ok, den_p, 1.0)), 0.0)


def _transmittance(c, e_ct, e, den_s, den_p):
    """(1 - rs^2 + 1 - rp^2) / 2 = 2 c e cos_t (1 / den_s^2 + e^2 / den_p^2), no subtraction.

    Written with the ratios c / den and e cos_t / den (each in [0, 1]), so cosines down to the
    smallest subnormal never square to 0 and divide by it."""
    return 2.0 * ((c / den_s) * (e_ct / den_s) + e * e * (c / den_p) * (e_ct / den_p))


def fresnel_dielectric(cos_i: np.ndarray, eta: np.ndarray | float) -> np.ndarray:
    """Unpolarised Fresnel reflectance of a dielectric interface; 1 under TIR.

    eta = n_interior / n_exterior; cos_i < 0 means the light arrives from the interior.
    """
    return dielectric_reflectance_transmittance(cos_i, eta)[0]


def fresnel_conductor(cos_i: np.ndarray, eta_complex: complex | np.ndarray) -> np.ndarray:
    """Unpolarised Fresnel reflectance of a conductor of complex relative index n + ik.

    Exact for any complex index (a real index gives the dielectric value); cos_i is taken
    as |cos_i| since light reaches a conductor only from the exterior.
    """
    n = np.asarray(eta_complex, dtype=np.complex128)
    rs, rp = fresnel_amplitudes(cos_i, n, (n - 1.0) * (n + 1.0))
    return 0.5 * (np.abs(rs) ** 2 + np.abs(rp) ** 2)


def fresnel_amplitudes(
    cos_i: np.ndarray, n: np.ndarray | complex, n2_minus_1: np.ndarray | complex
) -> tuple[np.ndarray, np.ndarray]:
    """Complex reflection amplitudes (r_s, r_p) toward a medium of relative index n (n + ik,
    k >= 0, fields ~ exp(-i omega t)); n2_minus_1 = n^2 - 1, exact (no cancellation near 1).

    r_s = (c - n cos_t)/(c + n cos_t), r_p = (n c - cos_t)/(n c + cos_t): the amplitudes in
    right-handed (s, p, k) frames of both beams with one s, so r_p = -r_s at normal incidence
    and r_p = 0 at Brewster's angle. n cos_t = sqrt(n^2 - 1 + c^2) on the principal branch,
    which is the evanescent wave under total internal reflection (|r_s| = |r_p| = 1 there).
    c = |cos_i|; where both denominators vanish (n = 1 at grazing) r_s = r_p = -1, the
    grazing limit.
    """
    c = np.abs(np.asarray(cos_i, dtype=np.float64))
    n = np.asarray(n, dtype=np.complex128)
    n2m1 = np.asarray(n2_minus_1, dtype=np.complex128)
    n2 = n * n
    root = np.sqrt(n2m1 + c * c)  # n cos_t
    den_s = c + root
    den_p = n2 * c + root
    ok = (den_s != 0) & (den_p != 0)
    matched = n2m1 == 0  # n = 1: rs = rp = 0 exactly; no complex 0 / 1e-320 (it overflows)
    den_s = np.where(ok & ~matched, den_s, 1.0)
    den_p = np.where(ok & ~matched, den_p, 1.0)
    # (c - n cos_t) / (c + n cos_t); divided twice, as den^2 underflows for den ~ 1e-300
    rs = -n2m1 / den_s / den_s
    rp = n2m1 * ((n2 + 1.0) * c * c - 1.0) / den_p / den_p
    return np.where(ok, rs, -1.0), np.where(ok, rp, -1.0)
