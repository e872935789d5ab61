"""The random walk's uniforms (numba): one sequential stream per batch, or keyed per walk.

What walk_kernel.walk_all draws from (draw). Sequential: the batch's own xoshiro256+
generator (numba's np.random.random cost 12 ns a draw, 1 ns here), seeded from the caller's
numpy Generator; the draws' order is the walk's. Keyed: each uniform a splitmix64 hash of
(key, walk index, event, slot), so walk j is the same path whatever the batch or the thread
(keyed.py takes the covariance from a prefix of the walks).
"""

from __future__ import annotations

import numpy as np

from model.bsdf.primitives import scalar

#: xoshiro256+'s shifts and rotation, as uint64 (numba would take a mixed int64 to float).
SHIFT_A, ROTATE, ROTATE_BACK, DROP = (np.uint64(k) for k in (17, 45, 19, 11))
GOLDEN = np.uint64(0x9E3779B97F4A7C15)
MIX_A = np.uint64(0xBF58476D1CE4E5B9)
MIX_B = np.uint64(0x94D049BB133111EB)
#: Uniforms reserved per event of a keyed walk, and what each slot draws: the free path, the
#: facet normal (two), the scattering (the Fresnel choice; the backwards proposal's side when
#: guided), the Russian roulette, the guided proposal's choice and its facet normal (two).
SLOTS = 8
HEIGHT, NORMAL_1, NORMAL_2, SCATTER, ROULETTE_DRAW, GUIDE, BACK_1, BACK_2 = range(SLOTS)


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
def key_of_walk(key, walk):
    """The hash key of walk index `walk` under the estimate's key."""
    return mix64(np.uint64(key) ^ mix64(np.uint64(walk) * GOLDEN))


@scalar
def draw(state, key, k, slot):
    """The uniform of `slot` at event k (1, 2, ...) of a walk: the next of the sequential
    generator `state` (4 uint64), or keyed by the walk's key where state is None (numba then
    compiles the keyed draw alone: a None argument prunes the branch)."""
    if state is None:
        return keyed_uniform(key, k * SLOTS + slot)
    return uniform(state)
