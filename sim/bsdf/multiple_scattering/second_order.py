"""The random walk's second scattering order by deterministic quadrature (no random numbers).

On a Smith microsurface the phase function does not depend on the height, so order 2 of
f |cos o| from wi towards wo is

    sum over branches b (reflected, transmitted) of the integral over the first event's
    outgoing direction w1 of  phase_b(wi -> w1) H_b(w1_z, wo) phase(-d1 -> wo),

d1 = w1 in the frame of the side it travels in. H is the walk's height expectation: the first
event's height CDF u1 has density a0 u^(a0 - 1) (a0 = -Lambda(-wi)); the second event follows
along d1 (u2 / u1 = exp(E / Lambda(d1)), forced to hit and weighted by the hit probability, as
the walk does) and wo escapes from it with G1. H depends on w1 only through its polar angle
(isotropic Lambda), so it is computed once per (polar node, branch, target) by Gauss-Legendre
rules over the two heights' uniforms; the direction integral is Gauss-Legendre in w1_z (split
at the horizon, where Lambda changes branch) times the periodic trapezoid rule in azimuth.
Orders >= 2 are then this plus the walk's orders >= 3 (lobe.higher_orders_at).
"""

from __future__ import annotations

import numpy as np

from sim.bsdf.multiple_scattering.micro import MicroConductor, MicroDielectric
from sim.bsdf.multiple_scattering.walk import flip

#: Gauss-Legendre nodes in w1_z per hemisphere, azimuth nodes of w1, nodes per height uniform.
POLAR_NODES = 64
AZIMUTH_NODES = 128
HEIGHT_NODES = 8


def _gauss_unit(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Legendre nodes and weights on [0, 1]."""
    x, w = np.polynomial.legendre.leggauss(n)
    return 0.5 * (x + 1.0), 0.5 * w


def _polar_nodes(polar: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Legendre nodes of w1_z in [-1, 0] and in [0, 1] (split at the horizon, where
    Lambda changes branch) and their weights."""
    x, w = _gauss_unit(polar)
    return np.concatenate([-x[::-1], x]), np.concatenate([w[::-1], w])


def _azimuth_nodes(azimuth: int) -> tuple[np.ndarray, np.ndarray]:
    """Azimuths psi of w1 about a target's azimuth and their weights: the periodic trapezoid
    rule in t with psi = t - sin(2t) / 2, which crowds the nodes about psi = 0 and pi, where
    the second event's phase function peaks (sharply for grazing directions), and keeps the
    rule spectrally convergent (the integrand stays smooth and periodic in t)."""
    t = 2.0 * np.pi * np.arange(azimuth) / azimuth
    return t - 0.5 * np.sin(2.0 * t), (1.0 - np.cos(2.0 * t)) * 2.0 * np.pi / azimuth


def _height_expectation(a0: float, lam1: np.ndarray, crossed: bool, lam_e: np.ndarray,
                        same: np.ndarray, nodes: int) -> np.ndarray:
    """H (p, m): the expectation over both events' heights of G1 = c^lam_e of wo leaving the
    second event, c its height CDF on wo's side (own side where same, else the other), for
    first directions of Lambda lam1 (p,) and targets (m,) of escape Lambda lam_e (p, m)."""
    x, w = _gauss_unit(nodes)
    s, t = (a.ravel() for a in np.meshgrid(x, x, indexing="ij"))
    weight = np.outer(w, w).ravel()
    log_u1 = np.log(s) / a0
    log_c1 = np.log(-np.expm1(log_u1)) if crossed else log_u1
    lam = lam1[:, None]
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        p_hit = np.where(lam > 0.0, -np.expm1(lam * log_c1[None, :]), 1.0)
        e = -np.log1p(-t[None, :] * p_hit)
        log_here = np.minimum(log_c1[None, :] + e / lam, 0.0)
        log_there = np.log(-np.expm1(log_here))
    good = np.isfinite(lam) & np.isfinite(log_here)
    q = np.where(good, weight * p_hit, 0.0)  # (p, nodes^2)
    here, there = np.where(good, log_here, -np.inf), np.where(good, log_there, 0.0)
    log_c = np.where(same[:, :, None], here[:, None, :], there[:, None, :])
    with np.errstate(over="ignore", invalid="ignore"):
        escape = np.where(lam_e[:, :, None] >= 0.0, np.exp(lam_e[:, :, None] * log_c), 0.0)
    return np.einsum("pk,pmk->pm", q, np.nan_to_num(escape))


def second_order(walker, wi: np.ndarray, targets: np.ndarray, polar: int = POLAR_NODES,
                 azimuth: int = AZIMUTH_NODES, heights: int = HEIGHT_NODES) -> np.ndarray:
    """Order 2 of f |cos o| from wi (3,) towards every target (m, 3) of a dielectric or
    conductor Smith microsurface (a Walker's slopes and micro, isotropic), by quadrature."""
    micro, slopes = walker.micro, walker.slopes
    if not isinstance(micro, (MicroConductor, MicroDielectric)):
        raise ValueError("second_order needs dielectric or conductor facets")
    wi, targets = np.asarray(wi, np.float64), np.asarray(targets, np.float64).reshape(-1, 3)
    if wi[2] <= 0.0:  # lit from below: the same walk in the mirrored world, eta inverted
        mirrored = MicroDielectric(1.0 / micro.eta) if micro.transmits else micro
        return second_order(_Walker(slopes, mirrored), flip(wi), flip(targets), polar,
                            azimuth, heights)
    a0 = -float(slopes.signed_lambda(-wi[None, :])[0])
    z, wz = _polar_nodes(polar)
    psi, wpsi = _azimuth_nodes(azimuth)
    sin_z = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    out = np.zeros(len(targets))
    for crossed in (False, True) if micro.transmits else (False,):
        # the second event's frame: d1 travels in it; its polar angle fixes Lambda(d1)
        d1_z = -z if crossed else z
        frame = flip(targets) if crossed else targets
        same = frame[:, 2] > 0.0
        lam_e = np.where(same, slopes.signed_lambda(frame), slopes.signed_lambda(flip(frame)))
        lam1 = slopes.signed_lambda(np.stack([sin_z, 0.0 * z, d1_z], axis=-1))
        h = _height_expectation(a0, lam1, crossed, np.broadcast_to(lam_e, (len(z), len(frame))),
                                np.broadcast_to(same, (len(z), len(frame))), heights)
        first = {}  # phase1 on the azimuth grid about each distinct target azimuth
        for j, target in enumerate(targets):
            key = round(float(np.arctan2(target[1], target[0])), 12)
            if key not in first:
                first[key] = _first_event(micro, slopes, wi, z, sin_z, key + psi, crossed)
            w1, phase1 = first[key]
            rows = np.flatnonzero(phase1 > 0.0)
            d1 = flip(w1[rows]) if crossed else w1[rows]
            w_in2 = -d1
            wl = np.broadcast_to(frame[j], w_in2.shape)
            here = np.full(len(rows), not crossed)
            if same[j]:
                phase2 = micro.phase_reflect(slopes, w_in2, wl, here, w_in2, False)
            elif micro.transmits:
                phase2 = micro.phase_transmit(slopes, w_in2, wl, here, False)
            else:
                continue
            weight = (wz[:, None] * wpsi[None, :] * h[:, j, None]).ravel()[rows]
            out[j] += np.sum(weight * phase1[rows] * phase2)
    return out


def _first_event(micro, slopes, wi: np.ndarray, z: np.ndarray, sin_z: np.ndarray,
                 phi: np.ndarray, crossed: bool) -> tuple[np.ndarray, np.ndarray]:
    """Directions w1 on the (polar z, azimuth phi) grid (flattened) and the first event's
    reflection (or, crossed, transmission) phase function from wi towards them."""
    w1 = np.stack([sin_z[:, None] * np.cos(phi)[None, :], sin_z[:, None] * np.sin(phi)[None, :],
                   np.broadcast_to(z[:, None], (len(z), len(phi)))], axis=-1).reshape(-1, 3)
    w_in = np.broadcast_to(wi, w1.shape)
    top = np.ones(len(w1), dtype=bool)
    if crossed:
        return w1, micro.phase_transmit(slopes, w_in, w1, top, False)
    return w1, micro.phase_reflect(slopes, w_in, w1, top, w_in, False)


class _Walker:
    """Slopes and micro-BSDF, as second_order reads them from a Walker."""

    def __init__(self, slopes, micro):
        self.slopes, self.micro = slopes, micro
