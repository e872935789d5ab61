"""The random walk compiled (numba): one walker, one walk at a time, for every estimator.

walk_path is the walk: from a direction and height on one side of the surface, free paths to
the next event (forced hits and Russian roulette when evaluating, the analog walk when
sampling), visible normals, reflection or refraction, order and cap, with the scalar formulas
of nee_kernel.py and visible_kernel.py. At each event it hands the event to the estimator it
was given, next-event estimation towards a set of Targets (one wo per walk, the targets every
walk shares, or the one target of a reverse walk), and it returns what the walk did (events,
first height, exit direction and weight, energy left at the cap). What differs between uses is
in three small records: Rules (forced or analog, orders, roulette, branch share), Guide (the
wo that guided next directions aim at, guiding_kernel.py) and the Stream of uniforms
(random_kernel.py: sequential or keyed). walk_batch drives it for Walker.run (whose numpy path
is the reference and the fallback for diffuse facets and without numba); keyed_kernel.py drives
it for the shared-path estimators of the tables and fits.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from model.bsdf.multiple_scattering.guiding import BACKWARDS
from model.bsdf.multiple_scattering.guiding_kernel import mixture_weight, sample_backwards
from model.bsdf.multiple_scattering.nee_kernel import (
    escape,
    facet_fresnel,
    next_event,
    projected_area,
    side_eta,
    surface,
    target_lambdas,
    unsigned_lambda,
)
from model.bsdf.multiple_scattering.random_kernel import (
    BACK_1,
    BACK_2,
    GUIDE,
    HEIGHT,
    NORMAL_1,
    NORMAL_2,
    ROULETTE_DRAW,
    SCATTER,
    Stream,
    draw,
)
from model.bsdf.multiple_scattering.visible_kernel import visible_normal
from model.bsdf.primitives import inlined, scalar, unit

#: What a batch does: follow the analog walk to its exit, score towards one wo per walk, or
#: score towards every one of a set of targets.
SAMPLE, EVALUATE, TARGETS = 0, 1, 2
LOG_2 = math.log(2.0)


class Rules(NamedTuple):
    """How a walk goes: forced hits (evaluating) or the analog walk; score only order `order`
    and stop there (0: every order from min_order); stop after max_order events (0: no cap);
    Russian roulette below weight `roulette`, played after scattering (late) or before the
    facet normal is drawn; dielectric branches drawn with probability at least `share`
    (0: by F)."""

    forced: bool
    order: int
    min_order: int
    max_order: int
    roulette: float
    late_roulette: bool
    share: float


class Guide(NamedTuple):
    """The wo (x, y, z) that guided next directions aim at, and its projected area |o_z| +
    cos_lambda(o); on: guide at all."""

    on: bool
    x: float
    y: float
    z: float
    area: float


class Targets(NamedTuple):
    """The next-event estimator: directions (m, 3), their unsigned_lambda (m,), and the row
    (m,) that each event's scores are added to."""

    directions: np.ndarray
    lam: np.ndarray
    row: np.ndarray


NO_GUIDE = Guide(False, 0.0, 0.0, 0.0, 0.0)


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
def event_area(s, ix, iy, iz, lam_up):
    """projected_area of the event's w_in = (ix, iy, iz) from its Lambda lam_up, which the
    walk has already computed (the full formula only on the horizon)."""
    if abs(iz) > 0.0:
        return max(iz, 0.0) + abs(iz) * lam_up
    return projected_area(s, ix, iy, iz)


@scalar
def branch_share(f, c, el, share):
    """The probability scatter reflects with at a dielectric facet of reflectance f and cosine
    c towards the relative index el: clip(f, share, 1 - share), f itself where only one branch
    exists (total internal reflection, f in {0, 1}) or share is 0."""
    if (1.0 - c * c) / (el * el) >= 1.0 or not 0.0 < f < 1.0:
        return f
    return min(max(f, share), 1.0 - share)


@inlined
def scatter(s, outside, ix, iy, iz, mx, my, mz, u, share):
    """Next direction from the phase function (micro.scatter), a dielectric facet's branch
    chosen with probability branch_share (the weight taking F / that, or (1 - F) / its
    complement; by F itself at share 0): (x, y, z, factor, crossed)."""
    c = ix * mx + iy * my + iz * mz
    if s.conductor:
        f = facet_fresnel(s, True, c, 1.0, 0.0)
        return 2.0 * c * mx - ix, 2.0 * c * my - iy, 2.0 * c * mz - iz, f, False
    el, elm1 = side_eta(s.eta, outside)
    c = min(max(c, 0.0), 1.0)
    f = facet_fresnel(s, True, c, el, elm1)
    q = branch_share(f, c, el, share)
    sin2_t = (1.0 - c * c) / (el * el)
    if u >= q and sin2_t < 1.0:
        cos_t = math.sqrt(max(0.0, 1.0 - sin2_t))
        k = c / el - cos_t
        x, y, z = unit(-ix / el + k * mx, -iy / el + k * my, -iz / el + k * mz)
        return x, y, z, (1.0 if q == f else (1.0 - f) / (1.0 - q)), True
    x, y, z = unit(2.0 * c * mx - ix, 2.0 * c * my - iy, 2.0 * c * mz - iz)
    return x, y, z, (1.0 if q == f else f / q), False


@inlined
def score(s, targets, beta, outside, ix, iy, iz, area, log_here, log_there):
    """Next-event estimation at one event: targets.row[t] += beta x phase towards direction t x
    its escape probability."""
    directions, lam, row = targets
    for t in range(directions.shape[0]):
        row[t] += beta * next_event(s, outside, ix, iy, iz, area, directions[t, 0],
                                    directions[t, 1], directions[t, 2], lam[t], log_here,
                                    log_there)


@inlined
def walk_path(s, stream, rules, guide, targets, outside, dx, dy, dz, cur, beta, k):
    """Walk on from direction d (local frame of its side, outside or not), log height CDF cur
    of that side, weight beta and k events done, scoring targets at every event Rules count:
    (events, log C1 of the first event's height (nan if none or k > 0), exit direction (world)
    and weight of an analog walk that left (nan and 0 otherwise), energy still inside at the
    cap). Evaluating, the roulette (unless late) comes after an event's score and before its
    facet normal, so an event it ends costs no normal and no scattering."""
    events, first = 0, math.nan
    ex, ey, ez, weight, truncated = math.nan, math.nan, math.nan, 0.0, 0.0
    while True:
        k += 1
        u = draw(stream, k, HEIGHT)
        lam_up = unsigned_lambda(s, dx, dy, dz)
        lam = lam_up if dz >= 0.0 else -1.0 - lam_up
        p_hit = hit_probability(lam, cur) if rules.forced else 1.0
        beta *= p_hit
        e = free_path(u, p_hit)
        new = math.inf if lam == 0.0 else cur + e / lam
        if not new < 0.0:
            if not rules.forced:
                ex, ey, ez, weight = dx, dy, (dz if outside else -dz), beta
            break
        other = 0.0 if s.conductor else log1mexp(new)  # the side below, if there is one
        events = k
        if k == 1:
            first = new if outside else other
        ix, iy, iz = -dx, -dy, -dz
        area = event_area(s, ix, iy, iz, lam_up)
        if k >= rules.min_order and (rules.order == 0 or rules.order == k):
            score(s, targets, beta, outside, ix, iy, iz, area, new, other)
        if rules.order and k >= rules.order:
            break
        if rules.forced and not rules.late_roulette and beta < rules.roulette:
            if draw(stream, k, ROULETTE_DRAW) * rules.roulette < beta:
                beta = rules.roulette
            else:
                break
        if guide.on and draw(stream, k, GUIDE) < BACKWARDS:  # only the proposal drawn is computed
            wx, wy, wz, crossed, ok = sample_backwards(
                s, outside, guide.x, guide.y, guide.z, draw(stream, k, SCATTER),
                draw(stream, k, BACK_1), draw(stream, k, BACK_2))
            factor = 1.0 if ok else 0.0  # a failed draw ends the walk (guiding.py)
        else:
            mx, my, mz = visible_normal(s, ix, iy, iz, draw(stream, k, NORMAL_1),
                                        draw(stream, k, NORMAL_2))
            wx, wy, wz, factor, crossed = scatter(s, outside, ix, iy, iz, mx, my, mz,
                                                  draw(stream, k, SCATTER), rules.share)
        if guide.on and factor > 0.0:
            factor = mixture_weight(s, outside, ix, iy, iz, area, guide, wx, wy, wz, crossed)
        beta *= factor
        if crossed:
            outside = not outside
            dx, dy, dz, cur = wx, wy, -wz, other
        else:
            dx, dy, dz, cur = wx, wy, wz, new
        if rules.max_order and k >= rules.max_order:
            truncated = beta * (1.0 - escape(s, dx, dy, dz, cur))
            break
        if rules.late_roulette and beta < rules.roulette:
            beta = rules.roulette if draw(stream, k, ROULETTE_DRAW) * rules.roulette < beta \
                else 0.0
        if not beta > 0.0:
            break
    return events, first, ex, ey, ez, weight, truncated


@scalar
def walk_batch(s, mode, guided, wi, wo, targets, u_first, order, max_order, min_order, roulette,
               state, value, exit_dir, weight, truncated, orders, first):
    """One walk from each row of wi on the Surface s, uniforms from the generator state
    (random_kernel.uniform; u_first (n, 3) or empty: the first event's); outputs as
    Walker.run's WalkResult (value (n, m))."""
    rules = Rules(mode != SAMPLE, order, min_order, max_order, roulette, False, 0.0)
    each = mode == EVALUATE  # one target per walk, its wo, which guiding aims at
    aims = wo if each else targets
    lam = target_lambdas(s, aims)
    none = np.empty(0)
    for i in range(wi.shape[0]):
        outside = wi[i, 2] > 0.0
        if s.conductor and not outside:
            continue
        lo, hi = (i, i + 1) if each else (0, aims.shape[0])
        guide = Guide(guided, wo[i, 0], wo[i, 1], wo[i, 2], abs(wo[i, 2]) * (1.0 + lam[i])) \
            if each else NO_GUIDE
        stream = Stream(False, np.uint64(0), state, u_first[i] if u_first.shape[0] else none)
        result = walk_path(s, stream, rules, guide, Targets(aims[lo:hi], lam[lo:hi], value[i]),
                           outside, -wi[i, 0], -wi[i, 1], -wi[i, 2] if outside else wi[i, 2],
                           0.0, 1.0, 0)
        orders[i], first[i] = result[0], result[1]
        exit_dir[i, 0], exit_dir[i, 1], exit_dir[i, 2], weight[i], truncated[i] = result[2:]


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
    walk_batch(surface(walker.slopes, walker.micro, unit_mode), mode,
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
