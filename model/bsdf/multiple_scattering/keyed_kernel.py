"""Shared-path walks towards many targets, and from many starts, keyed and branch-split (numba).

Both drive walk_kernel.walk_all with forced hits, unguided, next-event estimation at every
event of order >= min_order, and:

* a dielectric facet's branch chosen with probability clip(F, share, 1 - share) instead of F,
  the weight taking F / that (or (1 - F) / its complement). With F ~ 0.04 at glass, paths that
  reflect at an early event (those that reach the air side again and score large towards
  transmitted targets, or stay above and score towards reflected ones) are a few in a
  thousand by F and carry most of the variance; by the share they are common, with small
  weights;
* each uniform keyed by (key, walk index, event, slot) (random_kernel), so walk j is the same
  path whatever the batch size and any prefix of the walks is a sample of its own
  (keyed.keyed_walk_to_targets takes the covariance from one);
* Russian roulette played after scattering (Rules.late_roulette).

walk_from_starts is the reverse, for reciprocity: to estimate orders >= 3 of f(wi, wo) at many
wo for one wi, walk from the wo towards wi. Walk j starts from starts[j mod n]; its first event
(first_events: its height and scattered direction, the only part of a path that depends on
where it started) is weighted for every start b by the balance heuristic: the density of that
event from b over the sum of the densities all starts sample it with. Each estimate is unbiased
and uses every walk, for about 30 ns per start and walk. (Sharing only among nearby starts,
at any window from 0 to 60 degrees, gives less precision per CPU-second than sharing among
all.) In the transmitted wings at normal incidence the forward walk's scores are
heavy-tailed (rare grazing paths carry them) and the reverse walk's are not: it starts on those
paths.
"""

from __future__ import annotations

import math

import numpy as np

from model.bsdf.multiple_scattering.nee_kernel import (
    Surface,
    facet_fresnel,
    reflect_density,
    side_eta,
    target_lambdas,
    transmit_density,
    unsigned_lambda,
)
from model.bsdf.multiple_scattering.random_kernel import (
    HEIGHT,
    NORMAL_1,
    NORMAL_2,
    SCATTER,
    draw,
    key_of_walk,
)
from model.bsdf.multiple_scattering.visible_kernel import visible_normal
from model.bsdf.multiple_scattering.walk_kernel import (
    OUTCOMES,
    Rules,
    branch_share,
    event_area,
    free_path,
    log1mexp,
    paths,
    scatter,
    walk_all,
)
from model.bsdf.primitives import inlined, scalar

#: A keyed walk's given uniforms and per-walk outcome: none; and what walk_all takes for "no
#: direction of incidence" (every walk resumed) and "no walk resumed".
NOTHING_GIVEN, NO_OUTCOME = np.zeros((0, 3)), np.zeros((0, OUTCOMES))
NO_INCIDENCE, NONE_RESUMED = np.zeros((0, 3)), paths(0)


def keyed_rules(min_order: int, roulette: float, share: float) -> Rules:
    """The Rules of a keyed walk."""
    return Rules(True, False, False, 0, int(min_order), 0, float(roulette), True,
                 float(share))


def walk_targets(s: Surface, wi: np.ndarray, targets: np.ndarray, key: np.uint64, first: int,
                 min_order: int, roulette: float, share: float, value: np.ndarray) -> None:
    """value[j, t] = the NEE sum of orders >= min_order of walk first + j on the Surface s
    (from wi (3,)) towards target t (m, 3)."""
    walk_all(s, keyed_rules(min_order, roulette, share), wi.reshape(1, 3), NONE_RESUMED, key,
             first, None, NOTHING_GIVEN, targets, target_lambdas(s, targets), value,
             NO_OUTCOME)


@inlined
def first_event(s, el, elm1, ix, iy, iz, area, ox, oy, oz, crossed, share):
    """(physical density, density scatter samples it with) of a first event scattering i
    (projected area `area`) into o (local frame) by reflection or, crossed, transmission."""
    if crossed:
        density, c = transmit_density(s, el, ix, iy, iz, area, ox, oy, oz)
        if not density > 0.0:
            return 0.0, 0.0
        f = facet_fresnel(s, True, c, el, elm1)
        return (1.0 - f) * density, (1.0 - branch_share(f, c, el, share)) * density
    density, c = reflect_density(s, ix, iy, iz, area, ox, oy, oz)
    if not density > 0.0:
        return 0.0, 0.0
    f = facet_fresnel(s, True, c, el, elm1)
    return f * density, (1.0 if s.conductor else branch_share(f, c, el, share)) * density


@scalar
def first_events(s, starts, key, first, share, begin, physical, sampled):
    """The first event of walk first + j (from starts[(first + j) mod n], all on one side):
    begin[j] (PATH) where it leaves that event, beta 0 where no start could have sampled it;
    physical[j, b] x the density of its height from start b, and sampled[j] the sum over
    starts of the density they sample it with (the balance heuristic's weights)."""
    n = starts.shape[0]
    outside = starts[0, 2] > 0.0
    el, elm1 = side_eta(s.eta, outside)
    local = np.empty((n, 3))
    rate, area = np.empty(n), np.empty(n)
    for b in range(n):
        local[b, 0], local[b, 1], local[b, 2] = starts[b, 0], starts[b, 1], abs(starts[b, 2])
        lam_up = unsigned_lambda(s, local[b, 0], local[b, 1], local[b, 2])
        rate[b] = 1.0 + lam_up  # the first height's log C1 ~ Exp(rate), downwards from the top
        area[b] = event_area(s, local[b, 0], local[b, 1], local[b, 2], lam_up)
    for j in range(begin.shape[0]):
        walk_key = key_of_walk(key, first + j)
        a = (first + j) % n
        ix, iy, iz = local[a, 0], local[a, 1], local[a, 2]
        height = -free_path(draw(None, walk_key, 1, HEIGHT), 1.0) / rate[a]
        mx, my, mz = visible_normal(s, ix, iy, iz, draw(None, walk_key, 1, NORMAL_1),
                                    draw(None, walk_key, 1, NORMAL_2))
        ox, oy, oz, _, crossed = scatter(s, outside, ix, iy, iz, mx, my, mz,
                                         draw(None, walk_key, 1, SCATTER), share)
        total = 0.0
        for b in range(n):
            at_height = rate[b] * math.exp(rate[b] * height)
            p, d = first_event(s, el, elm1, local[b, 0], local[b, 1], local[b, 2], area[b], ox,
                               oy, oz, crossed, share)
            physical[j, b] = at_height * p
            total += at_height * d
        sampled[j] = total
        start = begin[j]
        start.k, start.beta = 1, 1.0 if total > 0.0 else 0.0
        start.outside, start.dx, start.dy = outside != crossed, ox, oy
        start.dz, start.cur = (-oz, log1mexp(height)) if crossed else (oz, height)


def walk_from_starts(s: Surface, starts: np.ndarray, target: np.ndarray, key: np.uint64,
                     first: int, min_order: int, roulette: float, share: float,
                     value: np.ndarray) -> None:
    """value[j, b] = walk first + j's NEE sum of orders >= min_order on the Surface s towards
    target (3,), as an estimate from start b (starts (n, 3), all on one side): the walk starts
    from starts[(first + j) mod n], its first event weighted for b by the balance heuristic
    over all starts. Unbiased for every b when the walks cover whole rounds of the starts."""
    n, walks = len(starts), len(value)
    if s.conductor and not starts[0, 2] > 0.0:
        return
    begin, physical, sampled = paths(walks), np.empty((walks, n)), np.empty(walks)
    first_events(s, starts, key, first, share, begin, physical, sampled)
    targets = np.ascontiguousarray(target, dtype=np.float64).reshape(1, 3)
    score = np.zeros((walks, 1))
    walk_all(s, keyed_rules(min_order, roulette, share), NO_INCIDENCE, begin, key, first,
             None, NOTHING_GIVEN, targets, target_lambdas(s, targets), score, NO_OUTCOME)
    live = score[:, 0] != 0.0
    value[live] = score[live] * n * physical[live] / sampled[live, None]
