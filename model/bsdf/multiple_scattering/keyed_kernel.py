"""Shared-path walks towards many targets, keyed random numbers and split branches (numba).

The walk of walk_kernel's TARGETS mode as it was when this kernel was written (forced hits,
Russian roulette after the scattering, unguided, next-event estimation at every event of
order >= min_order towards every target; walk_kernel's eval walk has since moved its roulette
before the facet normal) with two changes:

* a dielectric facet's branch is chosen with probability clip(F, share, 1 - share) instead of
  F, the weight taking F / that (or (1 - F) / its complement). With F ~ 0.04 at glass, paths
  that reflect at an early event (those that reach the air side again and score large towards
  transmitted targets, or stay above and score towards reflected ones) were a few in a
  thousand and carried most of the variance; now they are common, with small weights;
* each uniform is a hash of (key, walk index, event, slot) (splitmix64), not a draw from one
  sequential stream: walk j is the same path whatever the batch size, so any prefix of the
  walks is a sample of its own (keyed.keyed_walk_to_targets takes the covariance from one).
"""

from __future__ import annotations

import math

import numpy as np

from model.bsdf.multiple_scattering.nee_kernel import (
    facet_fresnel,
    next_event,
    side_eta,
    target_lambdas,
    unsigned_lambda,
)
from model.bsdf.multiple_scattering.visible_kernel import visible_normal
from model.bsdf.multiple_scattering.walk_kernel import (
    event_area,
    free_path,
    hit_probability,
    log1mexp,
    scatter,
)
from model.bsdf.primitives import inlined, scalar

GOLDEN = np.uint64(0x9E3779B97F4A7C15)
MIX_A = np.uint64(0xBF58476D1CE4E5B9)
MIX_B = np.uint64(0x94D049BB133111EB)
#: Uniforms reserved per event (height, two for the normal, Fresnel choice, roulette).
SLOTS = 8


@scalar
def mix64(z):
    """The splitmix64 finaliser: a bijective, well-mixed hash of a uint64."""
    z = (z ^ (z >> np.uint64(30))) * MIX_A
    z = (z ^ (z >> np.uint64(27))) * MIX_B
    return z ^ (z >> np.uint64(31))


@scalar
def keyed_uniform(walk_key, counter):
    """A uniform in [0, 1) (53 bits) for draw `counter` of the walk keyed walk_key."""
    z = mix64(walk_key + np.uint64(counter + 1) * GOLDEN)
    return float(z >> np.uint64(11)) * (1.0 / 9007199254740992.0)


@scalar
def branch_share(f, c, el, share):
    """The probability split_scatter reflects with at a dielectric facet of reflectance f and
    cosine c towards the relative index el: clip(f, share, 1 - share), f itself where only one
    branch exists (total internal reflection, f in {0, 1})."""
    if (1.0 - c * c) / (el * el) >= 1.0 or not 0.0 < f < 1.0:
        return f
    return min(max(f, share), 1.0 - share)


@scalar
def split_scatter(ndf, ax, ay, conductor, eta, has_f, n_c, outside, ix, iy, iz, mx, my, mz, u,
                  share):
    """scatter, with a dielectric facet's branch chosen with probability branch_share instead
    of F (the weight takes F / that or (1 - F) / its complement): (x, y, z, factor, crossed)."""
    if conductor:
        return scatter(ndf, ax, ay, conductor, eta, has_f, n_c, outside, ix, iy, iz, mx, my, mz,
                       u)
    c = min(max(ix * mx + iy * my + iz * mz, 0.0), 1.0)
    el, elm1 = side_eta(eta, outside)
    f = facet_fresnel(False, False, n_c, c, el, elm1)
    q = branch_share(f, c, el, share)
    if q == f:
        return scatter(ndf, ax, ay, conductor, eta, has_f, n_c, outside, ix, iy, iz, mx, my, mz,
                       u)
    x, y, z, _, crossed = scatter(ndf, ax, ay, conductor, eta, has_f, n_c, outside, ix, iy, iz,
                                  mx, my, mz, 0.0 if u < q else 1.0)
    return x, y, z, ((1.0 - f) / (1.0 - q) if crossed else f / q), crossed


@inlined
def walk_on(ndf, ax, ay, conductor, eta, has_f, n_c, targets, lam_t, walk_key, outside, dx, dy,
            dz, cur, beta, k, min_order, roulette, share, row):
    """Continue a keyed walk from direction d (local frame of its side), log height cur,
    weight beta and k events done: row[t] += its NEE scores of orders >= min_order towards
    every target."""
    while True:
        k += 1
        base = k * SLOTS
        lam_up = unsigned_lambda(ndf, ax, ay, dx, dy, dz)
        lam = lam_up if dz >= 0.0 else -1.0 - lam_up
        p_hit = hit_probability(lam, cur)
        beta *= p_hit
        new = cur + free_path(keyed_uniform(walk_key, base), p_hit) / lam \
            if lam != 0.0 else math.inf
        if not new < 0.0:
            break
        other = log1mexp(new)
        ix, iy, iz = -dx, -dy, -dz
        mx, my, mz = visible_normal(ndf, ax, ay, ix, iy, iz, keyed_uniform(walk_key, base + 1),
                                    keyed_uniform(walk_key, base + 2))
        area = event_area(ndf, ax, ay, ix, iy, iz, lam_up)
        if k >= min_order:
            for t in range(targets.shape[0]):
                row[t] += beta * next_event(ndf, ax, ay, conductor, eta, has_f, n_c, outside, ix,
                                            iy, iz, area, targets[t, 0], targets[t, 1],
                                            targets[t, 2], lam_t[t], new, other)
        wx, wy, wz, factor, crossed = split_scatter(
            ndf, ax, ay, conductor, eta, has_f, n_c, outside, ix, iy, iz, mx, my, mz,
            keyed_uniform(walk_key, base + 3), share)
        beta *= factor
        if crossed:
            outside = not outside
            dx, dy, dz, cur = wx, wy, -wz, other
        else:
            dx, dy, dz, cur = wx, wy, wz, new
        if beta < roulette:  # Russian roulette on low weights keeps the estimate unbiased
            beta = roulette if keyed_uniform(walk_key, base + 4) * roulette < beta else 0.0
        if not beta > 0.0:
            break


@scalar
def key_of_walk(key, walk):
    """The hash key of walk index `walk` under the estimate's key."""
    return mix64(np.uint64(key) ^ mix64(np.uint64(walk) * GOLDEN))


@scalar
def walk_targets(ndf, ax, ay, conductor, eta, has_f, n_c, wi, targets, key, first, min_order,
                 roulette, share, value):
    """value[j, t] = the NEE sum of orders >= min_order of walk first + j (from wi (3,))
    towards target t, uniforms keyed by (key, walk index, event, slot); dielectric branches
    chosen by split_scatter with `share`."""
    lam_t = target_lambdas(ndf, ax, ay, targets)
    start_out = wi[2] > 0.0
    if conductor and not start_out:
        return
    for j in range(value.shape[0]):
        walk_on(ndf, ax, ay, conductor, eta, has_f, n_c, targets, lam_t,
                key_of_walk(key, first + j), start_out, -wi[0], -wi[1],
                -wi[2] if start_out else wi[2], 0.0, 1.0, 0, min_order, roulette, share,
                value[j])
