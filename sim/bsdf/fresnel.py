"""Exact unpolarised Fresnel reflectance: dielectric (with total internal reflection) and conductor.

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
    e = np.where(cos_i < 0, 1.0 / eta, eta)
    c = np.abs(cos_i)
    s = np.sqrt(np.maximum((1.0 - c) * (1.0 + c), 0.0))  # sin of incidence
    e_ct2 = (e - s) * (e + s)  # (e cos_t)^2 = e^2 - sin_i^2, factored against cancellation
    tir = e_ct2 <= 0
    e_ct = np.sqrt(np.where(tir, 0.0, e_ct2))
    f, t = _dielectric_from_cosines(c, e_ct, e)
    return np.where(tir, 1.0, f), np.where(tir, 0.0, t)


def dielectric_transmittance(cos_i: np.ndarray, cos_t: np.ndarray, e: np.ndarray) -> np.ndarray:
    """1 - F from both |cosines| when the refracted one is already known (transmission lobe).

    e = n_t / n_i. Taking cos_t as given avoids the cancellation of sqrt(e^2 - sin_i^2) near
    the critical angle, so f_t(i, o) and f_t(o, i) are equally accurate.
    """
    return _dielectric_from_cosines(cos_i, e * cos_t, e)[1]


def _dielectric_from_cosines(c, e_ct, e):
    """(F, T) from c = |cos_i|, e_ct = e |cos_t| and e; (1, 0) where both denominators vanish."""
    e2c = e * e * c
    den_s = c + e_ct
    den_p = e2c + e_ct
    ok = (den_s > 0) & (den_p > 0)
    den_s = np.where(ok, den_s, 1.0)
    den_p = np.where(ok, den_p, 1.0)
    rs = (c - e_ct) / den_s
    rp = (e2c - e_ct) / den_p
    f = np.where(ok, 0.5 * (rs * rs + rp * rp), 1.0)
    t = np.where(ok, 2.0 * c * e_ct * (1.0 / (den_s * den_s) + e * e / (den_p * den_p)), 0.0)
    return f, t


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
    c = np.abs(np.asarray(cos_i, dtype=np.float64))
    n2 = np.asarray(eta_complex, dtype=np.complex128) ** 2
    root = np.sqrt(n2 - (1.0 - c) * (1.0 + c))  # n cos_t, principal branch (Re >= 0)
    rs = (c - root) / (c + root)
    rp = (n2 * c - root) / (n2 * c + root)
    return 0.5 * (np.abs(rs) ** 2 + np.abs(rp) ** 2)
