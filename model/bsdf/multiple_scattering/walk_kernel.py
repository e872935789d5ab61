"""The random walk compiled (numba): one walker for every estimator, one walk at a time.

walk_all is the walk, for a batch of walks each from the top of the side its direction of
incidence lights, or resumed where a PATH record says (side, direction, height, weight, events
done): free paths to the next event (forced hits and Russian roulette when evaluating, the
analog walk when sampling), visible normals, reflection or refraction, order and cap, with the
scalar formulas of nee_kernel.py and visible_kernel.py. Its events go to next-event estimation
towards target directions (one wo per walk, which guiding_kernel.py's proposal may aim at;
targets all walks share; or the one target of a reverse walk), and its outcome per walk
(events, first height, exit direction and weight, energy left at the cap) is the sampling
estimator. What differs between uses is a record of scalars, Rules (forced or analog, one
target per walk or all, guided, orders, roulette, branch share), where the walks start, and
their uniforms (random_kernel: a sequential generator, or keyed; numba compiles the two
apart). Arrays cross into it once per batch: numba counts references to a function's array
arguments at every call, which, once per walk, cost a third of a sampling walk.

run serves Walker.run (whose numpy path is the reference and the fallback for diffuse facets
and without numba); keyed_kernel.py serves the shared-path estimators of the tables and fits.
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
    draw,
    key_of_walk,
)
from model.bsdf.multiple_scattering.visible_kernel import visible_normal
from model.bsdf.primitives import fresnel_e_ct, inlined, scalar, unit

LOG_2 = math.log(2.0)


class Rules(NamedTuple):
    """How a batch's walks go: forced hits (evaluating) or the analog walk; each walk scoring
    its own row of the directions (each: one wo per walk, guided towards it when guided) or
    all of them; score only order `order` and stop there (0: every order from min_order);
    stop after max_order events (0: no cap); Russian roulette below weight `roulette`, played
    after scattering (late) or before the facet normal is drawn; dielectric branches drawn
    with probability at least `share` (0: by F)."""

    forced: bool
    each: bool
    guided: bool
    order: int
    min_order: int
    max_order: int
    roulette: float
    late_roulette: bool
    share: float


class Guide(NamedTuple):
    """The wo (x, y, z) that guided next directions aim at, and its projected area |o_z| +
    cos_lambda(o)."""

    x: float
    y: float
    z: float
    area: float


#: Where a walk resumes (a numpy record per walk): on the outside or not, travelling along d
#: (local frame of its side), from log height CDF cur of that side, with weight beta (0: not
#: walked) after k events.
PATH = np.dtype([("dx", np.float64), ("dy", np.float64), ("dz", np.float64),
                 ("cur", np.float64), ("beta", np.float64), ("k", np.int64),
                 ("outside", np.bool_)], align=True)
#: Columns of walk_all's per-walk outcome: events, log C1 of the first event's height (nan if
#: none or the walk started after one), exit direction (world; nan unless an analog walk left)
#: and weight, energy still inside at the cap, Smith Lambda of the exit direction
#: (unsigned_lambda, as the walk computed it for its last free path; nan if it did not leave).
EVENTS, FIRST, EXIT_X, EXIT_Y, EXIT_Z, WEIGHT, TRUNCATED, EXIT_LAMBDA = range(8)
OUTCOMES = 8


def paths(n: int) -> np.ndarray:
    """n PATH records, zeros."""
    return np.zeros(n, PATH)


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
    if share == 0.0 or not 0.0 < f < 1.0 or (1.0 - c * c) / (el * el) >= 1.0:
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
    f, e_ct = fresnel_e_ct(c, el, elm1)  # e_ct = el cos_t, 0 under total internal reflection
    q = branch_share(f, c, el, share)
    if u >= q and e_ct > 0.0:
        # el times the refracted direction, (c / el - cos_t) m - i / el, normalised
        k = c - e_ct
        x, y, z = unit(k * mx - ix, k * my - iy, k * mz - iz)
        return x, y, z, (1.0 if q == f else (1.0 - f) / (1.0 - q)), True
    x, y, z = unit(2.0 * c * mx - ix, 2.0 * c * my - iy, 2.0 * c * mz - iz)
    return x, y, z, (1.0 if q == f else f / q), False


@scalar
def walk_all(s, rules, wi, resumed, key, first, state, given, directions, lam, scores, out):
    """Walk j on the Surface s, for every row j of scores: from the top of the side wi[j]
    lights (wi[0] for all if wi has one row; none for a conductor lit from below) down into
    it, or where resumed[j] (PATH) says if wi has no rows; uniforms by random_kernel.draw (from
    state, or keyed by walk index first + j under key if state is None, which numba compiles
    apart; the first event's height and normal
    from given[j] if given has rows, for stratification), with next-event estimation
    at every event the Rules count: scores[j, t - lo] += beta x phase towards directions[t]
    (unsigned_lambda lam[t]) x its escape probability, t in [lo, hi) (j alone if rules.each,
    else all); out[j] (if out has rows) = the walk's outcome (EVENTS ... TRUNCATED; a walk of
    weight 0 is not walked). Evaluating, the roulette (unless late) comes after an event's
    score and before its facet normal, so an event it ends costs no normal and no
    scattering. Consecutive walks from one direction share its Lambda, computed once."""
    has_given = given.shape[0] > 0
    px = py = pz = start_lambda = math.nan  # the last start direction and its Lambda
    for j in range(scores.shape[0]):
        fresh = wi.shape[0] > 0
        if fresh:
            r = j if wi.shape[0] > 1 else 0
            outside = wi[r, 2] > 0.0
            dx, dy, dz = -wi[r, 0], -wi[r, 1], -wi[r, 2] if outside else wi[r, 2]
            cur, k = 0.0, 0
            beta = 0.0 if s.conductor and not outside else 1.0
            if not (dx == px and dy == py and dz == pz):  # once for walks from one direction
                px, py, pz = dx, dy, dz
                start_lambda = unsigned_lambda(s, dx, dy, dz)
        else:
            start = resumed[j]
            outside, dx, dy, dz, cur = start.outside, start.dx, start.dy, start.dz, start.cur
            beta, k = start.beta, start.k
        walk_key = key_of_walk(key, first + j) if state is None else np.uint64(0)
        events, first_height = 0, math.nan
        ex, ey, ez, weight, truncated = math.nan, math.nan, math.nan, 0.0, 0.0
        exit_lambda = math.nan
        lo, hi = (j, j + 1) if rules.each else (0, directions.shape[0])
        if rules.guided:
            guide = Guide(directions[j, 0], directions[j, 1], directions[j, 2],
                          abs(directions[j, 2]) * (1.0 + lam[j]))
        else:
            guide = Guide(0.0, 0.0, 0.0, 0.0)
        while beta > 0.0:
            k += 1
            given_here = k == 1 and has_given  # the caller's uniforms for event 1
            u = given[j, HEIGHT] if given_here else draw(state, walk_key, k, HEIGHT)
            lam_up = start_lambda if fresh else unsigned_lambda(s, dx, dy, dz)
            fresh = False
            lam_d = lam_up if dz >= 0.0 else -1.0 - lam_up
            p_hit = hit_probability(lam_d, cur) if rules.forced else 1.0
            beta *= p_hit
            e = free_path(u, p_hit)
            new = math.inf if lam_d == 0.0 else cur + e / lam_d
            if not new < 0.0:
                if not rules.forced:
                    ex, ey, ez, weight = dx, dy, (dz if outside else -dz), beta
                    exit_lambda = lam_up
                break
            if s.conductor:
                other = 0.0  # no side below
            elif cur == 0.0 and lam_d == -1.0 and p_hit == 1.0:
                other = math.log(u)  # from the top straight down C1 = 1 - u: log(1 - C1)
            else:
                other = log1mexp(new)
            events = k
            if k == 1:
                first_height = new if outside else other
            ix, iy, iz = -dx, -dy, -dz
            area = event_area(s, ix, iy, iz, lam_up)
            if k >= rules.min_order and (rules.order == 0 or rules.order == k):
                for t in range(lo, hi):
                    scores[j, t - lo] += beta * next_event(
                        s, outside, ix, iy, iz, area, directions[t, 0], directions[t, 1],
                        directions[t, 2], lam[t], new, other)
            if rules.order and k >= rules.order:
                break
            if rules.forced and not rules.late_roulette and beta < rules.roulette:
                if draw(state, walk_key, k, ROULETTE_DRAW) * rules.roulette < beta:
                    beta = rules.roulette
                else:
                    break
            # only the proposal drawn is computed
            if rules.guided and draw(state, walk_key, k, GUIDE) < BACKWARDS:
                u1 = draw(state, walk_key, k, SCATTER)
                u2 = draw(state, walk_key, k, BACK_1)
                u3 = draw(state, walk_key, k, BACK_2)
                wx, wy, wz, crossed, ok = sample_backwards(s, outside, guide.x, guide.y, guide.z,
                                                           u1, u2, u3)
                factor = 1.0 if ok else 0.0  # a failed draw ends the walk (guiding.py)
            else:
                u1 = given[j, NORMAL_1] if given_here else draw(state, walk_key, k,
                                                                NORMAL_1)
                u2 = given[j, NORMAL_2] if given_here else draw(state, walk_key, k,
                                                                NORMAL_2)
                mx, my, mz = visible_normal(s, ix, iy, iz, u1, u2)
                u3 = draw(state, walk_key, k, SCATTER)
                wx, wy, wz, factor, crossed = scatter(s, outside, ix, iy, iz, mx, my, mz, u3,
                                                      rules.share)
            if rules.guided and factor > 0.0:
                factor = mixture_weight(s, outside, ix, iy, iz, area, guide, wx, wy, wz,
                                        crossed)
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
                u = draw(state, walk_key, k, ROULETTE_DRAW)
                beta = rules.roulette if u * rules.roulette < beta else 0.0
        if out.shape[0]:
            out[j, EVENTS], out[j, FIRST], out[j, WEIGHT], out[j, TRUNCATED] = (
                events, first_height, weight, truncated)
            out[j, EXIT_X], out[j, EXIT_Y], out[j, EXIT_Z] = ex, ey, ez
            out[j, EXIT_LAMBDA] = exit_lambda


def run(walker, wi: np.ndarray, rng: np.random.Generator, wo, order, max_order, unit_mode,
        u_first, targets, min_order, roulette):
    """Walker.run by the kernel: the arrays of a WalkResult, in its field order."""
    n = wi.shape[0]
    wi = np.ascontiguousarray(wi, dtype=np.float64)
    each = wo is not None and targets is None  # one target per walk: its wo
    sampling = wo is None and targets is None
    aims = np.ascontiguousarray(wo if each else (np.zeros((0, 3)) if sampling else targets),
                                dtype=np.float64).reshape(-1, 3)
    s = surface(walker.slopes, walker.micro, unit_mode)
    value = np.zeros((n, 1 if each or sampling else len(aims)))
    out = np.empty((n, OUTCOMES))
    walk_all(s, Rules(not sampling, each, each and walker.guided, order or 0,
                      int(min_order), max_order or 0, float(roulette), False, 0.0),
             wi, paths(0), np.uint64(0), 0, rng.integers(0, 2**64, size=4, dtype=np.uint64),
             np.zeros((0, 3)) if u_first is None else np.ascontiguousarray(u_first, np.float64),
             aims, target_lambdas(s, aims), value, out)
    return (value if targets is not None else value[:, 0], out[:, EXIT_X:EXIT_Z + 1],
            out[:, WEIGHT], out[:, TRUNCATED], out[:, EVENTS].astype(np.int64), out[:, FIRST])
