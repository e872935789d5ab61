"""The focusing term of refraction: how much solid angle of half vectors a solid angle of
light directions covers with the view fixed, exactly (Walter et al. 2007, eq. 17) and as the
common real-time approximation quoted in issue 18, held against each other.

Conventions of model/lut: the view o is on the viewer's side, the light l beyond, eta =
n_beyond / n_view, and h the transmission half vector -(eta l + o) (normalised) towards o.
With c_o = o.h = cos x and c_l = |l.h| = sqrt(1 - sin^2 x / eta^2) (Snell at the facet),

    |d omega_h / d omega_l| = eta^2 c_l / (c_o - eta c_l)^2

(eq. 17 with the roles of i and o exchanged: the view is fixed and the light moves).
"""

from __future__ import annotations

import numpy as np

#: The empirical factor of the quoted approximation.
QUOTED_FACTOR = 4.0


def facet_cosine(x: np.ndarray, eta: np.ndarray) -> np.ndarray:
    """|l.h| of the light refracted through a facet at angle x from the view (NaN where the
    facet reflects it totally)."""
    s = np.sin(x) / eta
    with np.errstate(invalid="ignore"):
        return np.sqrt(1.0 - s * s)


def exact_jacobian(x: np.ndarray, eta: np.ndarray) -> np.ndarray:
    """|d omega_h / d omega_l| at facet angle x = angle(o, h) and index ratio eta (Walter's
    eq. 17 with the view fixed); NaN under total internal reflection at the facet."""
    x, eta = np.broadcast_arrays(np.asarray(x, np.float64), np.asarray(eta, np.float64))
    c_l = facet_cosine(x, eta)
    return eta * eta * c_l / (np.cos(x) - eta * c_l) ** 2


def quoted_derivative(x: np.ndarray, a: np.ndarray) -> np.ndarray:
    """The quoted expression verbatim: d(-o.l)/dx / sqrt(1 - (o.l)^2) for the relation
    -o.l = cos x sqrt(1 - a^2 sin^2 x) - a cos^2 x + a, a = n_view / n_beyond = 1 / eta;
    that is minus the derivative of the angle between l and -o with respect to x."""
    x, a = np.broadcast_arrays(np.asarray(x, np.float64), np.asarray(a, np.float64))
    s2, c2, cx2 = np.sin(2 * x), np.cos(2 * x), np.cos(x) ** 2
    with np.errstate(invalid="ignore"):
        numerator = a * s2 - s2 * (a * a * c2 + 1) / (
            np.sqrt(2.0) * np.sqrt(cx2 * (a * a * c2 - a * a + 2)))
        return numerator / np.sqrt(1 - (np.sqrt(cx2 * (a * a * cx2 - a * a + 1))
                                        - a * cx2 + a) ** 2)


def quoted_jacobian(x: np.ndarray, eta: np.ndarray) -> np.ndarray:
    """The approximation as quoted: QUOTED_FACTOR times the magnitude of quoted_derivative."""
    return QUOTED_FACTOR * np.abs(quoted_derivative(x, 1.0 / np.asarray(eta, np.float64)))


def facet_domain(etas: np.ndarray, angles: int = 256) -> tuple[np.ndarray, np.ndarray]:
    """(x, eta) grids over the facet angles that refract for each eta, x in [0, x_max):
    up to 90 degrees, or to the facet's critical angle asin(eta) when eta < 1 (endpoints
    excluded, where both sides are singular)."""
    etas = np.asarray(etas, np.float64)
    x_max = np.where(etas < 1.0, np.arcsin(np.minimum(etas, 1.0)), 0.5 * np.pi)
    frac = (np.arange(angles) + 0.5) / angles
    return frac[None, :] * x_max[:, None], np.broadcast_to(etas[:, None], (len(etas), angles))


def approximation_error(etas: np.ndarray, angles: int = 256) -> dict:
    """Relative error of quoted_jacobian against exact_jacobian over facet_domain(etas): its
    max and RMS, and the range of exact / quoted (a constant would mean only the factor is
    off)."""
    x, eta = facet_domain(etas, angles)
    exact, quoted = exact_jacobian(x, eta), quoted_jacobian(x, eta)
    rel = quoted / exact - 1.0
    ratio = exact / quoted
    return {"points": int(rel.size), "max_relative_error": float(np.max(np.abs(rel))),
            "rms_relative_error": float(np.sqrt(np.mean(rel * rel))),
            "exact_over_quoted": (float(ratio.min()), float(ratio.max()))}
