"""Compiled quadrature of the random walk's second order (second_order.py's fast route, numba).

One target at a time, the direction integral over the first event's outgoing w1 is cut into
cells on which the integrand is smooth, each integrated by a product of Gauss-Legendre rules in
w1's polar angle and azimuth with nodes in proportion to its size. The cuts: in the polar angle
where a phase function's support ends (its facet normal reaches the horizon: h_z is
proportional to z_in + eta z_out, so those edges are rings: the horizon, -wi_z or -wi_z / eta
for the first event, wo_z or eta wo_z for the second, mirrored as the side requires), in
azimuth at the planes of wi and of the target (where both events peak), and on the cones where
a Fresnel factor has its kink (total internal reflection) or a refraction its limit (kink_cones;
their rings' ends cut the polar angle too). Where lobes are narrow (small alpha, grazing light)
cells are graded geometrically (GRADE_*) about where the integrand lives: in the polar angle
about the events' specular peak rings, the horizon, the kink rings' ends and the half-vector
poles (w1 = -wi, w1 = the target: there a reflection's lobe closes into a wedge), in azimuth
about the first event's forward plane and the target's, the finer the nearer a pole.
Integrating in the polar angle rather than in w1_z keeps a cell smooth where an edge shrinks
onto a pole. A target in wi's plane makes the integrand symmetric about that plane, so half
the circle is integrated. The height expectation H is in closed form except for light
transmitted at both events (there second_order.py's product rule over the heights' uniforms),
once per polar node.
"""

from __future__ import annotations

import math

import numpy as np

from model.bsdf.multiple_scattering.nee_kernel import (
    phase_reflect,
    phase_transmit,
    projected_area,
    side_eta,
    unsigned_lambda,
)
from model.bsdf.primitives import log_beta, scalar

#: Graded cells about the peaks: the first GRADE_SCALE alpha from a peak ring (in the polar
#: angle) or a peak plane (in azimuth, divided by the ring's sine and, near a half-vector
#: pole, times the ring's polar distance from it), each GRADE_RATIO times the last, up to
#: GRADE_REACH radians; GRADE_LEVELS bounds the levels (room in the break arrays).
GRADE_SCALE = 0.25
GRADE_RATIO = 4.0
GRADE_REACH = 0.5
GRADE_LEVELS = 12
#: Polar nodes per radian grow as max(1, POLAR_ALPHA alpha) times `polar`: rough Beckmann
#: lobes meet in products of their tails, bumps narrower than the lobes.
POLAR_ALPHA = 3.0


@scalar
def signed_lambda(s, x, y, z):
    """Distribution.signed_lambda: Lambda >= 0 upward, -1 - Lambda(-w) downward, inf flat."""
    if z == 0.0:
        return math.inf
    up = unsigned_lambda(s, x, y, z)
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
def kink_cones(ix, iy, iz, tx, ty, tz, eta, conductor, crossed):
    """(axes (4, 3), cosines (4,), count) of the cones in w1 where an event's Fresnel factor
    or its refracted image ends with a kink: a dielectric reflection with total internal
    reflection (el < 1) at <w_in, h> = sqrt(1 - el^2), i.e. <w_in, w_out> = 1 - 2 el^2, and
    a refraction at its limit (the critical or the grazing facet), <w_out, -w_in> = el or
    1 / el; first event from wi, second towards the target (in d1's frame, then mirrored to
    w1's)."""
    axes, cosines, k = np.zeros((4, 3)), np.zeros(4), 0
    if conductor:
        return axes, cosines, k
    el1 = eta  # the first event is outside
    if crossed:
        axes[k, 0], axes[k, 1], axes[k, 2] = -ix, -iy, -iz
        cosines[k], k = (el1 if el1 < 1.0 else 1.0 / el1), k + 1
    elif el1 < 1.0:
        axes[k, 0], axes[k, 1], axes[k, 2] = ix, iy, iz
        cosines[k], k = 1.0 - 2.0 * el1 * el1, k + 1
    el2 = 1.0 / eta if crossed else eta
    lz = -tz if crossed else tz  # the target in d1's frame
    mirror = -1.0 if crossed else 1.0  # d1's frame back to w1's
    if lz > 0.0 and el2 < 1.0:  # <-d1, wo> = 1 - 2 el^2
        axes[k, 0], axes[k, 1], axes[k, 2] = tx, ty, mirror * lz
        cosines[k], k = 2.0 * el2 * el2 - 1.0, k + 1
    elif lz < 0.0:  # <wo, d1> = el or 1 / el
        axes[k, 0], axes[k, 1], axes[k, 2] = tx, ty, mirror * lz
        cosines[k], k = (el2 if el2 < 1.0 else 1.0 / el2), k + 1
    return axes, cosines, k


@scalar
def peak_rings(iz, tz, eta, conductor, crossed):
    """(w1_z (2,), count) of the rings through the events' specular peaks on a branch: the
    first event's mirror image (iz) or refraction of wi, the second's (on the reflected branch
    only: d1 travelling down onto the surface) mirror image of the target (-tz) or the
    direction in air that refracts into it."""
    rings, k = np.zeros(2), 0
    if crossed:
        s2 = (1.0 - iz * iz) / (eta * eta)
        if s2 < 1.0:
            rings[k], k = -math.sqrt(1.0 - s2), k + 1
        return rings, k
    rings[k], k = iz, k + 1
    if tz > 0.0:
        rings[k], k = -tz, k + 1
    elif not conductor:
        s2 = eta * eta * (1.0 - tz * tz)
        if s2 < 1.0:
            rings[k], k = -math.sqrt(1.0 - s2), k + 1
    return rings, k


@scalar
def graded(out, n, centre, scale, lo, hi, side):
    """out[n:] += centre + side * scale * GRADE_RATIO^k up to GRADE_REACH, on both sides where
    side is 0, that lie in (lo, hi): cells that widen geometrically away from a peak, so that
    any width from scale up gets a few nodes; returns the new n."""
    step = max(scale, GRADE_REACH * GRADE_RATIO ** (1 - GRADE_LEVELS))
    while step < GRADE_REACH:
        for x in (centre - step, centre + step):
            if lo < x < hi and side * (x - centre) >= 0.0:
                out[n] = x
                n += 1
        step *= GRADE_RATIO
    return n


@scalar
def half_vector_poles(iz, tz, crossed):
    """(w1_z (2,), count) of the points where a reflection's half vector is undefined: w1 = -wi
    (the first event's, on the reflected branch) and w1 = the target (the second event's, where
    it reflects). Near them the events' lobes close into a wedge as narrow as its distance to
    the point times alpha; both lie on a support edge, the first in the plane of wi, the second
    in the target's."""
    poles = np.full(2, math.nan)
    if not crossed:
        poles[0] = -iz
    if (tz > 0.0) != crossed:
        poles[1] = tz
    return poles


@scalar
def polar_breaks(iz, tz, eta, conductor, crossed, axes, cosines, cones, alpha):
    """The w1_z where an event's support ends (the horizon, -iz or -iz / eta, then tz or
    eta tz, mirrored as the side requires), where a kink cone's rings begin and end, and
    graded from GRADE_SCALE alpha about the horizon, the events' peak rings, the kink rings'
    ends and the half-vector poles (the last two into the side where the integrand lives);
    sorted, clamped to the branch's interval, with its ends."""
    hi = 0.0 if crossed else 1.0
    rings, count = peak_rings(iz, tz, eta, conductor, crossed)
    poles = half_vector_poles(iz, tz, crossed)
    edges = np.full(5 + (2 * cones + count + 3) * (1 + 2 * GRADE_LEVELS), -1.0)
    edges[1] = 0.0
    edges[2] = hi
    if crossed:
        edges[3], edges[4] = -iz / eta, (tz if tz < 0.0 else tz / eta)
    else:
        edges[3], edges[4] = -iz, (tz if (tz > 0.0 or conductor) else eta * tz)
    for c in range(cones):
        theta = math.acos(min(1.0, max(-1.0, axes[c, 2])))
        half = math.acos(min(1.0, max(-1.0, cosines[c])))
        edges[5 + 2 * c] = math.cos(theta + half)  # past a pole, the ring turns back
        edges[6 + 2 * c] = math.cos(theta - half)
    thetas = np.empty(edges.shape[0])
    n = 0
    for c in range(cones):  # the rings' ends: the cut ring's arcs shrink like a square root
        theta = math.acos(min(1.0, max(-1.0, axes[c, 2])))
        half = math.acos(min(1.0, max(-1.0, cosines[c])))
        n = graded(thetas, n, abs(theta - half), GRADE_SCALE * alpha, 0.0, math.pi, 1.0)
        n = graded(thetas, n, math.pi - abs(math.pi - theta - half), GRADE_SCALE * alpha, 0.0,
                   math.pi, -1.0)
    n = graded(thetas, n, 0.5 * math.pi, GRADE_SCALE * alpha, 0.0, math.pi, 0.0)  # Lambda
    for r in range(count):
        centre = math.acos(rings[r])
        thetas[n], n = centre, n + 1
        n = graded(thetas, n, centre, GRADE_SCALE * alpha, 0.0, math.pi, 0.0)
    for r in range(2):  # into the support only: the wedge's side
        if not math.isnan(poles[r]):
            inward = 1.0 if (r == 1 and not crossed) else -1.0
            n = graded(thetas, n, math.acos(poles[r]), GRADE_SCALE * alpha, 0.0, math.pi, inward)
    edges[5 + 2 * cones:5 + 2 * cones + n] = np.cos(thetas[:n])
    return np.sort(np.minimum(np.maximum(edges, -1.0), hi))


@scalar
def ring_breaks(plane_breaks, z, sin_z, axes, cosines, cones, peaks, scales):
    """The azimuths of one ring of w1 (polar z) at which to split it: the planes' (sorted,
    first to last, the last closing the range), graded from scales[k] on either side of the
    peak planes peaks[k] (the first event's forward plane, the target's), and where the kink
    cones cross the ring."""
    lo, hi = plane_breaks[0], plane_breaks[-1]
    n = plane_breaks.shape[0]
    out = np.empty(n + 2 * cones + peaks.shape[0] * 6 * GRADE_LEVELS)
    out[:n] = plane_breaks
    first = lo + (peaks[0] - lo) % (2.0 * math.pi)
    second = lo + (peaks[1] - lo) % (2.0 * math.pi)
    together = abs(first - second) < 1e-9
    for centre, scale in ((first, min(scales[0], scales[1]) if together else scales[0]),
                          (second, math.inf if together else scales[1])):
        for turn in (-2.0 * math.pi, 0.0, 2.0 * math.pi):
            n = graded(out, n, centre + turn, scale, lo, hi, 0.0)
    for c in range(cones):
        r = math.hypot(axes[c, 0], axes[c, 1]) * sin_z
        rhs = cosines[c] - axes[c, 2] * z
        if r <= 0.0 or abs(rhs) >= r:
            continue
        centre = math.atan2(axes[c, 1], axes[c, 0])
        turn = math.acos(rhs / r)
        for phi in (centre - turn, centre + turn):
            phi = lo + (phi - lo) % (2.0 * math.pi)
            if lo < phi < hi:
                out[n] = phi
                n += 1
    return np.sort(out[:n])


@scalar
def azimuth_scales(theta, sin_z, alpha, poles):
    """The first graded cell's width in azimuth on the ring at polar angle theta about each
    peak plane: GRADE_SCALE alpha / sin, shrunk near that plane's half-vector pole in
    proportion to the ring's polar distance from it."""
    scales = np.empty(2)
    for k in range(2):
        near = 1.0 if math.isnan(poles[k]) else min(1.0, abs(theta - math.acos(poles[k])))
        scales[k] = GRADE_SCALE * alpha * near / max(sin_z, 1e-9)
    return scales


@scalar
def cell_nodes(span, density, least, rules):
    """Gauss-Legendre nodes for a cell of this span at `density` nodes per unit: at least 4 and
    a third of `least` (the caller's nodes per radian: graded cells refine with the rest), at
    most the largest rule in `rules`."""
    floor = max(4, int(math.ceil(least / 3.0)))
    return min(rules.shape[0] - 1, max(floor, int(math.ceil(density * span))))


@scalar
def second_order_one(s, ix, iy, iz, a0, tx, ty, tz, polar, azimuth, xs, ws, hx, hw):
    """Order 2 of f |cos o| of the Surface s from wi = (ix, iy, iz), iz > 0, towards the world
    target t:
    `polar` nodes per radian of w1's polar angle (times max(1, POLAR_ALPHA alpha)) and
    `azimuth` per radian of its azimuth, per cell (at least 4 and a third of either), from the
    Gauss-Legendre rules on [0, 1] xs[n, :n], ws[n, :n]."""
    conductor, eta = s.conductor, s.eta
    area_i = projected_area(s, ix, iy, iz)
    el, elm1 = side_eta(eta, True)
    lam_e = unsigned_lambda(s, tx, ty, tz)
    flat_i = math.hypot(ix, iy) > 1e-12
    flat_t = math.hypot(tx, ty) > 1e-12
    phi_i = math.atan2(iy, ix) if flat_i else 0.0
    phi_t = math.atan2(ty, tx) if flat_t else phi_i
    if not flat_i:
        phi_i = phi_t
    gap = (phi_t - phi_i) % math.pi
    coplanar = min(gap, math.pi - gap) < 1e-9
    if coplanar:
        planes = np.array([phi_i, phi_i + math.pi])
        scale = 2.0
    else:
        planes = np.empty(5)
        planes[:4] = np.sort(phi_i + np.array([0.0, gap, math.pi, math.pi + gap]))
        planes[4] = planes[0] + 2.0 * math.pi
        scale = 1.0
    peaks = np.array([phi_i + math.pi, phi_t])
    total = 0.0
    for branch in range(1 if conductor else 2):
        crossed = branch == 1
        same = (tz < 0.0) if crossed else (tz > 0.0)
        el2, el2m1 = side_eta(eta, not crossed)
        lz = -tz if crossed else tz  # the target in d1's frame
        axes, cosines, cones = kink_cones(ix, iy, iz, tx, ty, tz, eta, conductor, crossed)
        edges = polar_breaks(iz, tz, eta, conductor, crossed, axes, cosines, cones,
                             s.alpha_x)
        poles = half_vector_poles(iz, tz, crossed)
        for cell in range(edges.shape[0] - 1):
            if edges[cell + 1] - edges[cell] <= 1e-12:
                continue
            # in the polar angle: smooth also where a support edge shrinks onto a pole
            t0 = math.acos(edges[cell + 1])
            span = math.acos(edges[cell]) - t0
            n_p = cell_nodes(span, polar * max(1.0, POLAR_ALPHA * s.alpha_x), polar, xs)
            for p in range(n_p):
                theta = t0 + span * xs[n_p, p]
                z, sin_z = math.cos(theta), math.sin(theta)
                dz = z if not crossed else -z  # d1's z in its own frame
                arcs = ring_breaks(planes, z, sin_z, axes, cosines, cones, peaks,
                                   azimuth_scales(theta, sin_z, s.alpha_x, poles))
                # the second event's w_in = -d1 in d1's frame: isotropic, one area per ring
                area = projected_area(s, sin_z, 0.0, -dz)
                ring = 0.0
                for a in range(arcs.shape[0] - 1):
                    f0, fspan = arcs[a], arcs[a + 1] - arcs[a]
                    if fspan <= 1e-12:
                        continue
                    n_q = cell_nodes(fspan, azimuth, azimuth, xs)
                    for q in range(n_q):
                        phi = f0 + fspan * xs[n_q, q]
                        ox, oy = sin_z * math.cos(phi), sin_z * math.sin(phi)
                        if crossed:
                            first = phase_transmit(s, el, elm1, ix, iy, iz, area_i, ox, oy, z)
                        else:
                            first = phase_reflect(s, True, el, elm1, ix, iy, iz, area_i, ox, oy,
                                                  z)
                        if first <= 0.0:
                            continue
                        # the second event (nee_kernel.next_event without the escape)
                        if lz > 0.0:
                            second = phase_reflect(s, True, el2, el2m1, -ox, -oy, -dz, area, tx,
                                                   ty, lz)
                        elif conductor:
                            second = 0.0
                        else:
                            second = phase_transmit(s, el2, el2m1, -ox, -oy, -dz, area, tx, ty,
                                                    lz)
                        ring += fspan * ws[n_q, q] * first * second
                if ring > 0.0:  # light leaving the glass backwards never is: no H for it
                    lam = signed_lambda(s, sin_z, 0.0, dz)
                    h = height_expectation(a0, lam, crossed, lam_e, same, hx, hw)
                    total += span * ws[n_p, p] * sin_z * h * ring
    return scale * total


@scalar
def second_order_all(s, wi, a0, targets, polar, azimuth, xs, ws, hx, hw, result):
    """result[t] = second_order_one of the Surface s towards every target (m, 3)."""
    for t in range(targets.shape[0]):
        result[t] = second_order_one(s, wi[0], wi[1], wi[2], a0, targets[t, 0], targets[t, 1],
                                     targets[t, 2], polar, azimuth, xs, ws, hx, hw)
