"""The random walk compiled, one walk at a time (numba): what Walker.run does, at native speed.

Walker.run's numpy path is the reference and the fallback (diffuse facets, no numba); this
kernel follows the same steps per walk (forced hits and Russian roulette when evaluating, the
roulette played before the facet normal is drawn, so an event it ends costs no normal and no
scattering; next-event estimation towards wo or towards every target, guided next directions
(guiding.py) towards wo, only the proposal drawn computed, the analog walk when sampling,
order and cap), with the scalar formulas of nee_kernel.py and visible_kernel.py, and its own
xoshiro256+ generator (uniform) seeded from the caller's numpy Generator (so a seed gives the
same walks, not the numpy path's numbers; numba's np.random.random cost 12 ns a draw, 1 ns here).
"""

from __future__ import annotations

import math

import numpy as np

from model.bsdf.multiple_scattering.guiding import BACKWARDS
from model.bsdf.multiple_scattering.nee_kernel import (
    escape,
    facet_fresnel,
    next_event,
    phase_reflect,
    phase_transmit,
    projected_area,
    refraction_normal,
    side_eta,
    surface_arguments,
    target_lambdas,
    unsigned_lambda,
)
from model.bsdf.multiple_scattering.visible_kernel import visible_normal
from model.bsdf.primitives import inlined, normal_density, scalar, unit

#: What a batch does: follow the analog walk to its exit, score towards one wo per walk, or
#: score towards every one of a set of targets.
SAMPLE, EVALUATE, TARGETS = 0, 1, 2
LOG_2 = math.log(2.0)
#: xoshiro256+'s shifts and rotation, as uint64 (numba would take a mixed int64 to float).
SHIFT_A, ROTATE, ROTATE_BACK, DROP = (np.uint64(k) for k in (17, 45, 19, 11))


@scalar
def uniform(state):
    """The next uniform in [0, 1) of the xoshiro256+ generator `state` (4 uint64, advanced in
    place; Blackman and Vigna 2018): its top 53 bits, in about 1 ns."""
    s0, s1, s2, s3 = state[0], state[1], state[2], state[3]
    result = s0 + s3
    t = s1 << SHIFT_A
    s2 ^= s0
    s3 ^= s1
    s1 ^= s2
    s0 ^= s3
    s2 ^= t
    state[0], state[1], state[2] = s0, s1, s2
    state[3] = (s3 << ROTATE) | (s3 >> ROTATE_BACK)
    return float(result >> DROP) * 2.0**-53


@scalar
def log1mexp(x):
    """log(1 - exp(x)) for x <= 0 (heights.log1mexp)."""
    if x > -LOG_2:
        return math.log(-math.expm1(x))
    return math.log1p(-math.exp(x))


@scalar
def one_minus_exp(x):
    """1 - exp(x) for x <= 0, to an ulp or two: by exp where exp(x) < 1/2 (libm's expm1 costs
    twice exp), by expm1 nearer 0."""
    return 1.0 - math.exp(x) if x < -LOG_2 else -math.expm1(x)


@scalar
def hit_probability(lam, cur):
    """The chance that a ray of signed Smith Lambda lam leaving the height of log CDF cur meets
    the surface again (1 downwards): what a forced hit weighs the walk by."""
    p_hit = one_minus_exp(lam * cur) if lam > 0.0 else 1.0
    return 1.0 if math.isnan(p_hit) else p_hit


@scalar
def free_path(u, p):
    """-log(1 - u p): the optical depth to the next event, from uniform u, given a hit of
    probability p. By log where 1 - u p is exact (u p >= 1/2, Sterbenz), log1p below."""
    x = u * p
    return -math.log(1.0 - x) if x >= 0.5 else -math.log1p(-x)


@inlined
def event_area(ndf, ax, ay, ix, iy, iz, lam_up):
    """projected_area of the event's w_in = (ix, iy, iz) from its Lambda lam_up, which the
    walk has already computed (the full formula only on the horizon)."""
    if abs(iz) > 0.0:
        return max(iz, 0.0) + abs(iz) * lam_up
    return projected_area(ndf, ax, ay, ix, iy, iz)


@inlined
def scatter(ndf, ax, ay, conductor, eta, has_f, n_c, outside, ix, iy, iz, mx, my, mz, u):
    """Next direction from the phase function (micro.scatter): (x, y, z, factor, crossed)."""
    c = ix * mx + iy * my + iz * mz
    if conductor:
        f = facet_fresnel(True, has_f, n_c, c, 1.0, 0.0)
        return 2.0 * c * mx - ix, 2.0 * c * my - iy, 2.0 * c * mz - iz, f, False
    el, elm1 = side_eta(eta, outside)
    c = min(max(c, 0.0), 1.0)
    f = facet_fresnel(False, False, n_c, c, el, elm1)
    sin2_t = (1.0 - c * c) / (el * el)
    if u >= f and sin2_t < 1.0:
        cos_t = math.sqrt(max(0.0, 1.0 - sin2_t))
        k = c / el - cos_t
        x, y, z = unit(-ix / el + k * mx, -iy / el + k * my, -iz / el + k * mz)
        return x, y, z, 1.0, True
    x, y, z = unit(2.0 * c * mx - ix, 2.0 * c * my - iy, 2.0 * c * mz - iz)
    return x, y, z, 1.0, False


@inlined
def adjoint_density(ndf, ax, ay, ix, iy, iz, ox, oy, oz, area, eta):
    """Density over w_in = i of the backwards-from-wo proposal (guiding.adjoint_density);
    area: projected_area of wo (above) or of -wo (below), |o_z| + cos_lambda(o) either way."""
    if oz > 0.0:
        hx, hy, hz = unit(ix + ox, iy + oy, iz + oz)
        if hz > 0.0 and ox * hx + oy * hy + oz * hz > 0.0 and area > 0.0:
            return normal_density(ndf, ax, ay, hx, hy, hz) / (4.0 * area)
        return 0.0
    hx, hy, hz, ci, co = refraction_normal(ix, iy, iz, ox, oy, oz, eta)
    if not (ci > 0.0 and co < 0.0 and hz > 0.0 and area > 0.0):
        return 0.0
    denom = ci + eta * co  # D_visible(-o, h) = -co D(h) / area
    value = -co * normal_density(ndf, ax, ay, hx, hy, hz) / area * ci / (denom * denom)
    return value if math.isfinite(value) else 0.0


@inlined
def sample_adjoint(ndf, ax, ay, ox, oy, oz, eta, u1, u2):
    """An arriving direction drawn backwards from wo (guiding.sample_adjoint): (x, y, z, ok)."""
    above = oz > 0.0
    s = 1.0 if above else -1.0
    mx, my, mz = visible_normal(ndf, ax, ay, s * ox, s * oy, s * oz, u1, u2)
    c = ox * mx + oy * my + oz * mz
    if above:
        x, y, z = 2.0 * c * mx - ox, 2.0 * c * my - oy, 2.0 * c * mz - oz
        ok = c > 0.0
    else:  # refract wo through the facet -m into a medium 1/eta times denser
        e = 1.0 / eta
        cn = -c
        sin2 = (1.0 - cn * cn) / (e * e)
        ok = sin2 < 1.0 and cn > 0.0
        k = cn / e - math.sqrt(max(0.0, 1.0 - sin2))
        x, y, z = unit(-ox / e - k * mx, -oy / e - k * my, -oz / e - k * mz)
    return x, y, z, ok and math.isfinite(x) and math.isfinite(y) and math.isfinite(z)


@inlined
def sample_backwards(ndf, ax, ay, conductor, eta, outside, ox, oy, oz, u1, u2, u3):
    """The guided proposal's backwards-from-wo draw (guiding.guided_scatter): a next direction
    in this side's frame whose arrival at the next event m sends into wo, the next event on
    the far side when u1 < 1/2 (dielectric): (x, y, z, crossed, ok)."""
    crossed = (not conductor) and u1 < 0.5
    side = outside != crossed
    e_side = side_eta(eta, side)[0] if not conductor else 1.0
    bx, by, bz, ok = sample_adjoint(ndf, ax, ay, ox, oy, oz if side else -oz, e_side, u2, u3)
    return -bx, -by, (bz if crossed else -bz), crossed, ok  # travel along minus the arrival


@inlined
def mixture_weight(ndf, ax, ay, conductor, eta, has_f, n_c, outside, ix, iy, iz, area, ox, oy,
                   oz, area_o, wx, wy, wz, crossed):
    """The walk's weight factor for next direction w however drawn, by one-sample MIS of the
    phase function and the backwards proposal (guiding.guided_scatter): phase (with F) over
    the mixture density. area_o: |o_z| + cos_lambda(o)."""
    el, elm1 = side_eta(eta, outside)
    if crossed:
        p_phase = phase_transmit(ndf, ax, ay, el, elm1, ix, iy, iz, area, wx, wy, wz)
        p_energy = p_phase
    else:
        p_phase = phase_reflect(ndf, ax, ay, conductor, False, n_c, el, elm1, ix, iy, iz, area,
                                wx, wy, wz)
        p_energy = phase_reflect(ndf, ax, ay, conductor, has_f, n_c, el, elm1, ix, iy, iz,
                                 area, wx, wy, wz) if has_f else p_phase
    next_side = outside != crossed
    nz = oz if next_side else -oz
    e_next = side_eta(eta, next_side)[0] if not conductor else 1.0
    arz = wz if crossed else -wz  # arriving direction in the next event's frame
    p_adj = adjoint_density(ndf, ax, ay, -wx, -wy, arz, ox, oy, nz, area_o, e_next)
    if not conductor:
        p_adj *= 0.5
    mixture = (1.0 - BACKWARDS) * p_phase + BACKWARDS * p_adj
    return p_energy / mixture if mixture > 0.0 else 0.0


@scalar
def walk_batch(ndf, ax, ay, conductor, eta, has_f, n_c, mode, guide, wi, wo, targets, u_first,
               order, max_order, min_order, roulette, state, value, exit_dir, weight, truncated,
               orders, first):
    """One walk from each row of wi, uniforms from the generator state (uniform); outputs as
    Walker.run's WalkResult (value (n, m))."""
    forced = mode != SAMPLE
    lam_t = target_lambdas(ndf, ax, ay, targets)
    lam_o = target_lambdas(ndf, ax, ay, wo)
    for i in range(wi.shape[0]):
        outside = wi[i, 2] > 0.0
        if conductor and not outside:
            continue
        if mode == EVALUATE:  # wo's Lambda and projected area, the same from either side
            area_o = abs(wo[i, 2]) * (1.0 + lam_o[i])
        dx, dy = -wi[i, 0], -wi[i, 1]
        dz = -wi[i, 2] if outside else wi[i, 2]
        cur = 0.0  # log C1 of the height on this side (h = +inf above, -inf below)
        beta = 1.0
        k = 0
        while True:
            k += 1
            given = k == 1 and u_first.shape[0] > 0  # the caller's uniforms for event 1
            ua = u_first[i, 0] if given else uniform(state)
            lam_up = unsigned_lambda(ndf, ax, ay, dx, dy, dz)
            lam = lam_up if dz >= 0.0 else -1.0 - lam_up
            if forced:
                p_hit = hit_probability(lam, cur)
                beta *= p_hit
                e = free_path(ua, p_hit)
            else:
                e = free_path(ua, 1.0)
            new = math.inf if lam == 0.0 else cur + e / lam
            if not new < 0.0:
                if not forced:
                    exit_dir[i, 0], exit_dir[i, 1] = dx, dy
                    exit_dir[i, 2] = dz if outside else -dz
                    weight[i] = beta
                break
            other = 0.0 if conductor else log1mexp(new)  # the side below, if there is one
            orders[i] = k
            if k == 1:
                first[i] = new if outside else other
            ix, iy, iz = -dx, -dy, -dz
            area = event_area(ndf, ax, ay, ix, iy, iz, lam_up)
            if k >= min_order and (order == 0 or order == k):
                if mode == EVALUATE:
                    value[i, 0] += beta * next_event(ndf, ax, ay, conductor, eta, has_f, n_c,
                                                     outside, ix, iy, iz, area, wo[i, 0],
                                                     wo[i, 1], wo[i, 2], lam_o[i], new, other)
                elif mode == TARGETS:
                    for t in range(targets.shape[0]):
                        value[i, t] += beta * next_event(ndf, ax, ay, conductor, eta, has_f,
                                                         n_c, outside, ix, iy, iz, area,
                                                         targets[t, 0], targets[t, 1],
                                                         targets[t, 2], lam_t[t], new, other)
            if order and k >= order:
                break
            if forced and beta < roulette:  # Russian roulette before scattering: a walk it
                if uniform(state) * roulette < beta:  # ends costs no normal, no scatter
                    beta = roulette
                else:
                    break
            if guide and uniform(state) < BACKWARDS:  # only the proposal drawn is computed
                wx, wy, wz, crossed, ok = sample_backwards(
                    ndf, ax, ay, conductor, eta, outside, wo[i, 0], wo[i, 1], wo[i, 2],
                    uniform(state), uniform(state), uniform(state))
                factor = 1.0 if ok else 0.0  # a failed draw ends the walk (guiding.py)
            else:
                ub = u_first[i, 1] if given else uniform(state)
                uc = u_first[i, 2] if given else uniform(state)
                mx, my, mz = visible_normal(ndf, ax, ay, ix, iy, iz, ub, uc)
                wx, wy, wz, factor, crossed = scatter(ndf, ax, ay, conductor, eta, has_f, n_c,
                                                      outside, ix, iy, iz, mx, my, mz,
                                                      uniform(state))
            if guide and factor > 0.0:
                factor = mixture_weight(ndf, ax, ay, conductor, eta, has_f, n_c, outside, ix, iy,
                                        iz, area, wo[i, 0], wo[i, 1], wo[i, 2], area_o, wx, wy,
                                        wz, crossed)
            beta *= factor
            if crossed:
                outside = not outside
                dx, dy, dz = wx, wy, -wz
                cur = other
            else:
                dx, dy, dz = wx, wy, wz
                cur = new
            if max_order and k >= max_order:
                truncated[i] = beta * (1.0 - escape(ndf, ax, ay, dx, dy, dz, cur))
                break
            if not beta > 0.0:
                break


def run(walker, wi: np.ndarray, rng: np.random.Generator, wo, order, max_order, unit_mode,
        u_first, targets, min_order, roulette):
    """Walker.run by the kernel: the arrays of a WalkResult, in its field order."""
    n = wi.shape[0]
    mode = SAMPLE if wo is None and targets is None else (EVALUATE if targets is None
                                                          else TARGETS)
    value = np.zeros((n, 1 if targets is None else len(targets)))
    exit_dir = np.full((n, 3), np.nan)
    weight, truncated = np.zeros(n), np.zeros(n)
    orders = np.zeros(n, dtype=np.int64)
    first = np.full(n, np.nan)
    empty = np.zeros((0, 3))
    walk_batch(*surface_arguments(walker.slopes, walker.micro, unit_mode), mode,
               mode == EVALUATE and walker.guided,
               np.ascontiguousarray(wi, dtype=np.float64),
               empty if wo is None else np.ascontiguousarray(wo, dtype=np.float64),
               empty if targets is None else np.ascontiguousarray(targets, dtype=np.float64),
               empty if u_first is None else np.ascontiguousarray(u_first, dtype=np.float64),
               order or 0, max_order or 0, int(min_order), float(roulette),
               rng.integers(0, 2**64, size=4, dtype=np.uint64), value, exit_dir, weight,
               truncated, orders, first)
    return (value if targets is not None else value[:, 0], exit_dir, weight, truncated, orders,
            first)
