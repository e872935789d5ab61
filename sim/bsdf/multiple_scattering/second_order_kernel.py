"""Compiled quadrature of the random walk's second order (second_order.py's fast route, numba).

One target at a time, the direction integral over the first event's outgoing w1 is split in
w1_z at every place where a phase function's support ends (its facet normal reaches the
horizon: h_z is proportional to z_in + eta z_out, so those edges are lines of constant w1_z:
the horizon, -wi_z and -wi_z / eta for the first event, and for the second event wo_z or
eta wo_z, mirrored as the side requires), and in azimuth at the planes of wi and of the target
(where both events peak); on every cell the product of Gauss-Legendre rules then sees a
smooth integrand (up to the kinks where Fresnel reaches total internal reflection, which
make light from below converge slowest). A target in wi's plane makes the integrand
symmetric about that plane, so half the circle is integrated. The height expectation H is in
closed form except for light transmitted at both events (there second_order.py's product
rule over the heights' uniforms), once per polar node and target.
"""

from __future__ import annotations

import math

import numpy as np

from sim.bsdf.multiple_scattering.nee_kernel import (
    next_event,
    phase_reflect,
    phase_transmit,
    projected_area,
    side_eta,
    unsigned_lambda,
)
from sim.bsdf.primitives import cos_lambda, log_beta, scalar


@scalar
def signed_lambda(ndf, ax, ay, x, y, z):
    """Distribution.signed_lambda: Lambda >= 0 upward, -1 - Lambda(-w) downward, inf flat."""
    if z == 0.0:
        return math.inf
    up = cos_lambda(ndf, ax, ay, x, y, z) / abs(z)
    return up if z > 0.0 else -1.0 - up


@scalar
def numeric_height_expectation(a0, lam, crossed, lam_e, same, hx, hw):
    """H of one first direction (Lambda lam of d1) and one target (escape Lambda lam_e, on
    d1's side when same) by the product rule hx, hw over both heights' uniforms:
    second_order._height_expectation for one (p, m)."""
    total = 0.0
    for i in range(hx.shape[0]):
        log_u1 = math.log(hx[i]) / a0
        log_c1 = math.log(-math.expm1(log_u1)) if crossed else log_u1
        p_hit = -math.expm1(lam * log_c1) if lam > 0.0 else 1.0
        for j in range(hx.shape[0]):
            log_here = min(log_c1 - math.log1p(-hx[j] * p_hit) / lam, 0.0)
            if not (math.isfinite(lam) and math.isfinite(log_here)):
                continue
            log_c = log_here if same else math.log(-math.expm1(log_here))
            escape = math.exp(lam_e * log_c) if lam_e >= 0.0 else 0.0
            if math.isfinite(escape):
                total += hw[i] * hw[j] * p_hit * escape
    return total


@scalar
def digamma(x):
    """psi(x) for x > 0: recurrence up to 6, then the asymptotic series (error below 1e-11)."""
    r = 0.0
    while x < 6.0:
        r -= 1.0 / x
        x += 1.0
    f = 1.0 / (x * x)
    return r + math.log(x) - 0.5 / x - f * (1.0 / 12.0 - f * (1.0 / 120.0 - f * (
        1.0 / 252.0 - f * (1.0 / 240.0 - f / 132.0))))


@scalar
def beta_slope(p1, p2, q):
    """(B(p1, q) - B(p2, q)) / (p1 - p2) for p, q >= 1: the difference quotient, or the
    derivative B (psi(p) - psi(p + q)) at the midpoint where p1 and p2 nearly cancel."""
    if abs(p1 - p2) > 1e-4 * max(p1, p2):
        return (math.exp(log_beta(p1, q)) - math.exp(log_beta(p2, q))) / (p1 - p2)
    m = 0.5 * (p1 + p2)
    return math.exp(log_beta(m, q)) * (digamma(m) - digamma(m + q))


@scalar
def height_expectation(a0, lam, crossed, lam_e, same, hx, hw):
    """H in closed form where it has one, else numeric_height_expectation (transmitted
    first, out through the other side second). Reflected first, the second event's height
    CDF x has the density a0 lam / (a0 + lam) x^(a0 - 1) upward (lam > 0) and a0 |lam|
    (x^(|lam| - 1) - x^(a0 - 1)) / (a0 - |lam|) downward, so G1 = x^lam_e or (1 - x)^lam_e
    integrates to powers and Beta functions; transmitted first and out on the same side, the
    forced hit's uniform and then the first height integrate in turn to a Beta difference."""
    if not (math.isfinite(lam) and math.isfinite(lam_e)) or lam == 0.0:
        return 0.0
    if crossed:
        if same:
            return -a0 * lam * beta_slope(lam_e + 1.0, lam + 1.0, a0)
        return numeric_height_expectation(a0, lam, crossed, lam_e, same, hx, hw)
    if lam > 0.0:
        if same:
            return a0 * lam / ((a0 + lam) * (a0 + lam_e))
        return a0 * lam / (a0 + lam) * math.exp(log_beta(a0, lam_e + 1.0))
    down = -lam
    if same:
        return a0 * down / ((down + lam_e) * (a0 + lam_e))
    return -a0 * down * beta_slope(down, a0, lam_e + 1.0)


@scalar
def polar_breaks(iz, tz, eta, conductor, crossed):
    """The w1_z in (-1, 1) where an event's support ends, for incidence z iz > 0 and target z
    tz, on the reflected (w1 anywhere) or the transmitted (w1 below) branch; sorted, with the
    ends of the branch's interval."""
    if crossed:
        edges = np.array([-1.0, 0.0, -iz / eta, tz if tz < 0.0 else tz / eta])
    else:
        edges = np.array([-1.0, 0.0, 1.0, -iz, tz if (tz > 0.0 or conductor) else eta * tz])
    return np.sort(np.minimum(np.maximum(edges, -1.0), 0.0 if crossed else 1.0))


@scalar
def second_order_one(ndf, ax, ay, conductor, eta, has_f, n_c, ix, iy, iz, a0, tx, ty,
                     tz, px, pw, qx, qw, hx, hw):
    """Order 2 of f |cos o| from wi = (ix, iy, iz), iz > 0, towards the world target t, with
    px, pw the polar rule per segment and qx, qw the azimuth rule per arc on [0, 1]."""
    area_i = projected_area(ndf, ax, ay, ix, iy, iz)
    el, elm1 = side_eta(eta, True)
    lam_t = unsigned_lambda(ndf, ax, ay, tx, ty, tz)
    lam_e = lam_t
    flat_i = math.hypot(ix, iy) > 1e-12
    flat_t = math.hypot(tx, ty) > 1e-12
    phi_i = math.atan2(iy, ix) if flat_i else 0.0
    phi_t = math.atan2(ty, tx) if flat_t else phi_i
    if not flat_i:
        phi_i = phi_t
    gap = (phi_t - phi_i) % math.pi
    coplanar = min(gap, math.pi - gap) < 1e-9
    if coplanar:
        arcs = np.array([phi_i, phi_i + math.pi])
        scale = 2.0
    else:
        arcs = np.empty(5)
        arcs[:4] = np.sort(np.array([phi_i, phi_t, phi_i + math.pi, phi_t + math.pi])
                           % (2.0 * math.pi))
        arcs[4] = arcs[0] + 2.0 * math.pi
        scale = 1.0
    total = 0.0
    for branch in range(1 if conductor else 2):
        crossed = branch == 1
        same = (tz < 0.0) if crossed else (tz > 0.0)
        edges = polar_breaks(iz, tz, eta, conductor, crossed)
        for s in range(edges.shape[0] - 1):
            z0, span = edges[s], edges[s + 1] - edges[s]
            if span <= 1e-12:
                continue
            for p in range(px.shape[0]):
                z = z0 + span * px[p]
                sin_z = math.sqrt(max(0.0, 1.0 - z * z))
                dz = z if not crossed else -z  # d1's z in its own frame
                lam = signed_lambda(ndf, ax, ay, sin_z, 0.0, dz)
                h = height_expectation(a0, lam, crossed, lam_e, same, hx, hw)
                if h == 0.0:
                    continue
                ring = 0.0
                for a in range(arcs.shape[0] - 1):
                    f0, fspan = arcs[a], arcs[a + 1] - arcs[a]
                    for q in range(qx.shape[0]):
                        phi = f0 + fspan * qx[q]
                        ox, oy = sin_z * math.cos(phi), sin_z * math.sin(phi)
                        if crossed:
                            first = phase_transmit(ndf, ax, ay, el, elm1, ix, iy, iz, area_i,
                                                   ox, oy, z)
                        else:
                            first = phase_reflect(ndf, ax, ay, conductor, has_f, n_c, el, elm1,
                                                  ix, iy, iz, area_i, ox, oy, z)
                        if first <= 0.0:
                            continue
                        # the second event: w_in = -d1 in d1's frame, the escape left out
                        wx, wy, wz = -ox, -oy, -dz
                        area = projected_area(ndf, ax, ay, wx, wy, wz)
                        ring += fspan * qw[q] * first * next_event(
                            ndf, ax, ay, conductor, eta, has_f, n_c, not crossed, wx, wy, wz,
                            area, tx, ty, tz, lam_t, 0.0, 0.0)
                total += span * pw[p] * h * ring
    return scale * total


@scalar
def second_order_all(ndf, ax, ay, conductor, eta, has_f, n_c, wi, a0, targets, px, pw, qx, qw,
                     hx, hw, result):
    """result[t] = second_order_one towards every target (m, 3)."""
    for t in range(targets.shape[0]):
        result[t] = second_order_one(ndf, ax, ay, conductor, eta, has_f, n_c, wi[0],
                                     wi[1], wi[2], a0, targets[t, 0], targets[t, 1],
                                     targets[t, 2], px, pw, qx, qw, hx, hw)
