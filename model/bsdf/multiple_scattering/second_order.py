"""The random walk's second scattering order by deterministic quadrature (no random numbers).

On a Smith microsurface the phase function does not depend on the height, so order 2 of
f |cos o| from wi towards wo is

    sum over branches b (reflected, transmitted) of the integral over the first event's
    outgoing direction w1 of  phase_b(wi -> w1) H_b(w1_z, wo) phase(-d1 -> wo),

d1 = w1 in the frame of the side it travels in. H is the walk's height expectation: the first
event's height CDF u1 has density a0 u^(a0 - 1) (a0 = -Lambda(-wi)); the second event follows
along d1 (u2 / u1 = exp(E / Lambda(d1)), forced to hit and weighted by the hit probability, as
the walk does) and wo escapes from it with G1. H depends on w1 only through its polar angle
(isotropic Lambda). second_order is the compiled route (second_order_kernel: H in closed
form where it has one; cells in w1's polar angle and azimuth cut per target at every support
edge of both events and at the Fresnel and refraction kink cones, graded about the lobes'
peaks, Gauss-Legendre nodes in proportion to a cell's size, POLAR_NODES and AZIMUTH_NODES per
radian);
second_order_reference is the numpy route it was checked against: H by Gauss-Legendre rules
over the two heights' uniforms, once per (polar node, branch, target), times Gauss-Legendre
in w1_z (split only at the horizon, where Lambda changes branch) and in azimuth on the arcs
between the planes of wi and of the targets (where the phase functions peak), converging
like 1 / nodes.
Orders >= 2 are then this plus the walk's orders >= 3 (lobe.higher_orders_at).
"""

from __future__ import annotations

import functools

import numpy as np

from model.bsdf.multiple_scattering import nee_kernel, second_order_kernel
from model.bsdf.multiple_scattering.energy import gauss_legendre_unit
from model.bsdf.multiple_scattering.micro import MicroConductor, MicroDielectric
from model.bsdf.multiple_scattering.walk import Walker, flip

#: Gauss-Legendre nodes per radian of w1's polar angle and of its azimuth in each cell (at
#: least 4, at most MAX_CELL_NODES; compiled route), per height uniform (both routes).
POLAR_NODES = 12
AZIMUTH_NODES = 12
MAX_CELL_NODES = 128
HEIGHT_NODES = 8
#: The numpy reference's nodes in w1_z per hemisphere and of w1's azimuth (all arcs).
REFERENCE_POLAR_NODES = 128
REFERENCE_AZIMUTH_NODES = 128


def _polar_nodes(polar: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Legendre nodes of w1_z in [-1, 0] and in [0, 1] (split at the horizon, where
    Lambda changes branch) and their weights."""
    x, w = gauss_legendre_unit(polar)
    return np.concatenate([-x[::-1], x]), np.concatenate([w[::-1], w])


def _azimuth_nodes(breaks: np.ndarray, azimuth: int) -> tuple[np.ndarray, np.ndarray]:
    """Azimuths of w1 and their weights: Gauss-Legendre on each arc between the break azimuths
    (those of the planes of wi and of the targets through the normal, both ways), where the
    two events' phase functions peak (sharply for grazing directions): the rule crowds its
    nodes there and no cell straddles a peak."""
    edges = np.unique(np.round(np.mod(breaks, 2.0 * np.pi), 12))
    edges = np.append(edges, edges[0] + 2.0 * np.pi)
    x, w = gauss_legendre_unit(max(8, azimuth // (len(edges) - 1)))
    spans = np.diff(edges)
    phi = (edges[:-1, None] + spans[:, None] * x[None, :]).ravel()
    return phi, (spans[:, None] * w[None, :]).ravel()


def _height_expectation(a0: float, lam1: np.ndarray, crossed: bool, lam_e: np.ndarray,
                        same: np.ndarray, nodes: int) -> np.ndarray:
    """H (p, m): the expectation over both events' heights of G1 = c^lam_e of wo leaving the
    second event, c its height CDF on wo's side (own side where same, else the other), for
    first directions of Lambda lam1 (p,) and targets (m,) of escape Lambda lam_e (p, m)."""
    x, w = gauss_legendre_unit(nodes)
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


def supports(walker) -> bool:
    """True when second_order can integrate this walker's microsurface (dielectric or conductor
    facets, isotropic slopes)."""
    return (isinstance(walker.micro, (MicroConductor, MicroDielectric))
            and walker.slopes.alpha_x == walker.slopes.alpha_y)


def _lit_from_above(walker: Walker, wi: np.ndarray, targets: np.ndarray
                    ) -> tuple[Walker, np.ndarray, np.ndarray]:
    """(walker, wi, targets) with wi above: lit from below, the same walk in the mirrored
    world, eta inverted."""
    micro, slopes = walker.micro, walker.slopes
    if not supports(walker):
        raise ValueError("second_order needs dielectric or conductor facets, isotropic slopes")
    wi, targets = np.asarray(wi, np.float64), np.asarray(targets, np.float64).reshape(-1, 3)
    if wi[2] > 0.0:
        return walker, wi, targets
    mirrored = MicroDielectric(1.0 / micro.eta) if micro.transmits else micro
    return Walker(slopes, mirrored, guided=False), flip(wi), flip(targets)


def second_order(walker: Walker, wi: np.ndarray, targets: np.ndarray,
                 polar: int = POLAR_NODES, azimuth: int = AZIMUTH_NODES,
                 heights: int = HEIGHT_NODES) -> np.ndarray:
    """Order 2 of f |cos o| from wi (3,) towards every target (m, 3) of a dielectric or
    conductor Smith microsurface (a Walker, isotropic slopes), by quadrature: compiled
    (second_order_kernel, `polar` nodes per radian of w1's polar angle and `azimuth` per
    radian of its azimuth in each cell), else the numpy reference at its own node counts
    (polar and azimuth mean nodes per hemisphere and per circle there: they are not passed)."""
    walker, wi, targets = _lit_from_above(walker, wi, targets)
    if not nee_kernel.supports(walker.slopes, walker.micro):
        return second_order_reference(walker, wi, targets, heights=heights)
    xs, ws = _rules(MAX_CELL_NODES)
    hx, hw = gauss_legendre_unit(heights)
    a0 = -float(walker.slopes.signed_lambda(-wi[None, :])[0])
    out = np.empty(len(targets))
    second_order_kernel.second_order_all(
        nee_kernel.surface(walker.slopes, walker.micro), wi, a0,
        np.ascontiguousarray(targets), float(polar), float(azimuth), xs, ws, hx, hw, out)
    return out


@functools.cache
def _rules(largest: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Legendre rules on [0, 1] of every size up to `largest`: nodes xs[n, :n], weights
    ws[n, :n]."""
    xs, ws = np.zeros((largest + 1, largest)), np.zeros((largest + 1, largest))
    for n in range(1, largest + 1):
        xs[n, :n], ws[n, :n] = gauss_legendre_unit(n)
    return xs, ws


def second_order_reference(walker: Walker, wi: np.ndarray, targets: np.ndarray,
                           polar: int = REFERENCE_POLAR_NODES,
                           azimuth: int = REFERENCE_AZIMUTH_NODES,
                           heights: int = HEIGHT_NODES) -> np.ndarray:
    """second_order by numpy on one product rule per plane of targets (w1_z split only at the
    horizon, azimuth arcs between the planes of wi and of the targets): the independent
    reference of the compiled route, converging like 1 / nodes."""
    walker, wi, targets = _lit_from_above(walker, wi, targets)
    # targets in one plane through the normal share an azimuth grid (crowded about the plane)
    plane = np.round(np.mod(np.arctan2(targets[:, 1], targets[:, 0]), np.pi), 9)
    out = np.zeros(len(targets))
    for key in np.unique(plane):
        rows = np.flatnonzero(plane == key)
        out[rows] = _second_order_in_plane(walker, wi, targets[rows], float(key), polar,
                                           azimuth, heights)
    return out


def _second_order_in_plane(walker: Walker, wi: np.ndarray, targets: np.ndarray, plane: float,
                           polar: int, azimuth: int, heights: int) -> np.ndarray:
    """second_order for targets in the plane through the normal at azimuth `plane`."""
    micro, slopes = walker.micro, walker.slopes
    a0 = -float(slopes.signed_lambda(-wi[None, :])[0])
    z, wz = _polar_nodes(polar)
    breaks = [plane, plane + np.pi]
    if np.hypot(wi[0], wi[1]) > 1e-12:
        breaks += [np.arctan2(wi[1], wi[0]), np.arctan2(wi[1], wi[0]) + np.pi]
    phi, wpsi = _azimuth_nodes(np.array(breaks), azimuth)
    sin_z = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    w1 = np.stack([sin_z[:, None] * np.cos(phi)[None, :], sin_z[:, None] * np.sin(phi)[None, :],
                   np.broadcast_to(z[:, None], (len(z), len(phi)))], axis=-1).reshape(-1, 3)
    node_weight = (wz[:, None] * wpsi[None, :]).ravel()
    polar_index = np.repeat(np.arange(len(z)), len(phi))
    w_in = np.broadcast_to(wi, w1.shape)
    top = np.ones(len(w1), dtype=bool)
    out = np.zeros(len(targets))
    for crossed in (False, True) if micro.transmits else (False,):
        if crossed:
            phase1 = micro.phase_transmit(slopes, w_in, w1, top, False)
        else:
            phase1 = micro.phase_reflect(slopes, w_in, w1, top, w_in, False)
        live = np.flatnonzero(phase1 > 0.0)
        d1 = flip(w1[live]) if crossed else w1[live]  # in the frame of the side it travels in
        here = np.full(len(live), not crossed)
        # phase(-d1 -> target) with the escape left out (log CDF 0), for every live node
        phase2 = walker.next_event_all(-d1, -d1, here, targets, np.zeros(len(live)),
                                       np.zeros(len(live)), False)
        frame = flip(targets) if crossed else targets  # the targets in d1's frame
        same = frame[:, 2] > 0.0
        lam_e = np.where(same, slopes.signed_lambda(frame), slopes.signed_lambda(flip(frame)))
        lam1 = slopes.signed_lambda(np.stack([sin_z, 0.0 * z, -z if crossed else z], axis=-1))
        h = _height_expectation(a0, lam1, crossed, np.broadcast_to(lam_e, (len(z), len(frame))),
                                np.broadcast_to(same, (len(z), len(frame))), heights)
        amplitude = node_weight[live] * phase1[live]
        out += np.einsum("r,rm,rm->m", amplitude, phase2, h[polar_index[live]])
    return out
