"""Keyed walks from many starts towards one target, shared by the starts (numba).

The reverse of keyed_kernel.walk_targets, for reciprocity: to estimate orders >= 3 of f(wi, wo)
at many wo for one wi, walk from the wo towards wi. Started from one direction each, such walks
serve one point; here walk j starts from starts[j mod n] and its first event (its height and
its scattered direction, the only part of a path that depends on where it started) is weighted
for every start b by the balance heuristic: the density of that event from b over the sum of
the densities all starts sample it with. Each estimate is unbiased and uses every walk, for
about 30 ns per start and walk. (Sharing only among nearby starts was tried: at every window
from 0 to 60 degrees it gave less precision per CPU-second than sharing among all.) In the
transmitted wings at normal incidence the forward walk's scores are heavy-tailed (rare grazing
paths carry them) and the reverse walk's are not: it starts on those paths.
"""

from __future__ import annotations

import math

import numpy as np

from model.bsdf.multiple_scattering.keyed_kernel import (
    SLOTS,
    branch_share,
    key_of_walk,
    keyed_uniform,
    split_scatter,
    walk_on,
)
from model.bsdf.multiple_scattering.nee_kernel import (
    facet_fresnel,
    reflect_density,
    side_eta,
    target_lambdas,
    transmit_density,
    unsigned_lambda,
)
from model.bsdf.multiple_scattering.visible_kernel import visible_normal
from model.bsdf.multiple_scattering.walk_kernel import event_area, free_path, log1mexp
from model.bsdf.primitives import inlined, scalar


@inlined
def first_event(ndf, ax, ay, conductor, has_f, n_c, el, elm1, ix, iy, iz, area, ox, oy, oz,
                crossed, share):
    """(physical density, density split_scatter samples it with) of a first event scattering
    i (projected area `area`) into o (local frame) by reflection or, crossed, transmission."""
    if crossed:
        density, c = transmit_density(ndf, ax, ay, el, ix, iy, iz, area, ox, oy, oz)
        if not density > 0.0:
            return 0.0, 0.0
        f = facet_fresnel(False, False, n_c, c, el, elm1)
        return (1.0 - f) * density, (1.0 - branch_share(f, c, el, share)) * density
    density, c = reflect_density(ndf, ax, ay, ix, iy, iz, area, ox, oy, oz)
    if not density > 0.0:
        return 0.0, 0.0
    f = facet_fresnel(conductor, has_f, n_c, c, el, elm1)
    return f * density, (1.0 if conductor else branch_share(f, c, el, share)) * density


@scalar
def walk_from_starts(ndf, ax, ay, conductor, eta, has_f, n_c, starts, target, key, first,
                     min_order, roulette, share, value):
    """value[j, b] = walk first + j's NEE sum of orders >= min_order towards target (3,), as an
    estimate from start b (starts (n, 3), all on one side): the walk starts from
    starts[(first + j) mod n], its first event weighted for b by the balance heuristic over
    all starts. Unbiased for every b when the walks cover whole rounds of the starts."""
    n = starts.shape[0]
    targets = np.empty((1, 3))
    targets[0, 0], targets[0, 1], targets[0, 2] = target[0], target[1], target[2]
    lam_t = target_lambdas(ndf, ax, ay, targets)
    outside = starts[0, 2] > 0.0
    if conductor and not outside:
        return
    el, elm1 = side_eta(eta, outside)
    local = np.empty((n, 3))
    rate, area = np.empty(n), np.empty(n)
    for b in range(n):
        local[b, 0], local[b, 1], local[b, 2] = starts[b, 0], starts[b, 1], abs(starts[b, 2])
        lam_up = unsigned_lambda(ndf, ax, ay, local[b, 0], local[b, 1], local[b, 2])
        rate[b] = 1.0 + lam_up  # the first height's log C1 ~ Exp(rate), downwards from the top
        area[b] = event_area(ndf, ax, ay, local[b, 0], local[b, 1], local[b, 2], lam_up)
    physical = np.empty(n)
    score = np.zeros(1)
    for j in range(value.shape[0]):
        walk_key = key_of_walk(key, first + j)
        a = (first + j) % n
        ix, iy, iz = local[a, 0], local[a, 1], local[a, 2]
        height = -free_path(keyed_uniform(walk_key, SLOTS), 1.0) / rate[a]
        mx, my, mz = visible_normal(ndf, ax, ay, ix, iy, iz, keyed_uniform(walk_key, SLOTS + 1),
                                    keyed_uniform(walk_key, SLOTS + 2))
        ox, oy, oz, _, crossed = split_scatter(ndf, ax, ay, conductor, eta, has_f, n_c, outside,
                                               ix, iy, iz, mx, my, mz,
                                               keyed_uniform(walk_key, SLOTS + 3), share)
        sampled = 0.0
        for b in range(n):
            at_height = rate[b] * math.exp(rate[b] * height)
            p, d = first_event(ndf, ax, ay, conductor, has_f, n_c, el, elm1, local[b, 0],
                               local[b, 1], local[b, 2], area[b], ox, oy, oz, crossed, share)
            physical[b] = at_height * p
            sampled += at_height * d
        if not sampled > 0.0:
            continue
        score[0] = 0.0
        if crossed:
            walk_on(ndf, ax, ay, conductor, eta, has_f, n_c, targets, lam_t, walk_key,
                    not outside, ox, oy, -oz, log1mexp(height), 1.0, 1, min_order, roulette,
                    share, score)
        else:
            walk_on(ndf, ax, ay, conductor, eta, has_f, n_c, targets, lam_t, walk_key, outside,
                    ox, oy, oz, height, 1.0, 1, min_order, roulette, share, score)
        if score[0] != 0.0:
            for b in range(n):
                value[j, b] = score[0] * n * physical[b] / sampled
