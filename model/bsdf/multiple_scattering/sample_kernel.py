"""RandomWalkBSDF.sample and approximate_pdf compiled (numba): one walk per sample, its lobes and
its approximate density in one pass, with no numpy pass per sample.

approximate_density is approximate_pdf at one pair: order 1 of the walk in closed form
(kernels.dielectric_unit / conductor_unit: the height-correlated single-scattering model, F = 1
for a conductor) plus the orders >= 2 as a cosine lobe carrying their share, interpolated in a
table over the incidence of wi (model.MASS_NODES_DEG); model.py keeps the numpy version, the
reference and the path without numba. sample walks the batch with walk_kernel.walk_all (the
analog walk, the caller's uniforms for the first event) and then finishes each walk: exit
direction, weight (0 outside the parent's lobes or when the walk did not leave) and the density
at it, computed as approximate_pdf computes it from the same numbers (the Lambda of the exit
direction the walk computed for its last free path among them), so the two agree to the last
bit.
"""

from __future__ import annotations

import math

import numpy as np

from model.bsdf.constants import Masking, Sampling
from model.bsdf.multiple_scattering.nee_kernel import AVAILABLE, surface, unsigned_lambda
from model.bsdf.multiple_scattering.walk_kernel import (
    EXIT_LAMBDA,
    EXIT_X,
    EXIT_Y,
    EXIT_Z,
    OUTCOMES,
    WEIGHT,
    Rules,
    paths,
    walk_all,
)
from model.bsdf.primitives import cos_lambda, scalar, unit
from model.kernel_cache import compiled

#: Walks per block: each block is walked, then finished, while its outcome is in cache and in
#: one scratch array (the whole batch's outcome at once is 64 bytes a walk of fresh memory,
#: about 20 ns a sample to fault in, write and read back).
BLOCK = 8192
#: What walk_all takes for "no target directions" (a sampling walk scores nothing).
NO_TARGETS, NO_LAMBDAS = np.zeros((0, 3)), np.zeros(0)
CORRELATED, VISIBLE = int(Masking.CORRELATED), int(Sampling.VISIBLE)
INV_PI = 1.0 / math.pi


@scalar
def interpolate(nodes, table, x):
    """table at x, linear between nodes (increasing), its end values beyond them (np.interp)."""
    if x <= nodes[0]:
        return table[0]
    for j in range(1, nodes.shape[0]):
        if x <= nodes[j]:
            t = (x - nodes[j - 1]) / (nodes[j] - nodes[j - 1])
            return table[j - 1] + t * (table[j] - table[j - 1])
    return table[nodes.shape[0] - 1]


@scalar
def lobe_mass(nodes, shares, vz):
    """The share of orders >= 2 at the incidence of unit wi (z component vz): shares[0] lit
    from outside, shares[1] from inside, interpolated in degrees."""
    theta = math.degrees(math.acos(min(abs(vz), 1.0)))
    return interpolate(nodes, shares[0] if vz > 0.0 else shares[1], theta)


if AVAILABLE:
    from model.bsdf.kernels import conductor_unit, dielectric_unit

    @compiled(error_model="numpy")
    def approximate_density(s, mass, vx, vy, vz, li, wx, wy, wz, lo):
        """approximate_pdf at unit wi = v, wo = w, with li, lo their |z| Lambda (cos_lambda)
        and mass the orders >= 2's share at wi (lobe_mass): order 1 of the walk plus a lobe
        mass |cos o| / pi above a conductor, mass |cos o| / (2 pi) either side of glass."""
        cos_o = abs(wz)
        if s.conductor:
            first = conductor_unit(vx, vy, vz, wx, wy, wz, s.ndf, s.alpha_x, s.alpha_y, False,
                                   0j, CORRELATED, VISIBLE, False, li, lo)
            return first * cos_o + (mass * cos_o * INV_PI if vz > 0.0 and wz > 0.0 else 0.0)
        first = dielectric_unit(vx, vy, vz, wx, wy, wz, s.ndf, s.alpha_x, s.alpha_y, s.eta,
                                CORRELATED, True, True, VISIBLE, False, li, lo)
        return first * cos_o + mass * cos_o * (0.5 * INV_PI)

    @compiled(error_model="numpy")
    def densities(s, nodes, shares, wi, wo, lambdas, result):
        """result[j] = approximate_density at row j of wi (row 0 if it has one) and of wo, each
        normalised; wo's Lambda is unsigned_lambda of wo[j] as given (it does not depend on the
        length), or lambdas[j] where not nan: a walk's own, computed from the same numbers.
        Through rows that repeat the row before, wi's share and Lambda are computed once."""
        px = py = pz = math.nan
        vx = vy = vz = li = mass = 0.0
        for j in range(result.shape[0]):
            r = j if wi.shape[0] > 1 else 0
            if not (wi[r, 0] == px and wi[r, 1] == py and wi[r, 2] == pz):
                px, py, pz = wi[r, 0], wi[r, 1], wi[r, 2]
                vx, vy, vz = unit(px, py, pz)
                li = cos_lambda(s.ndf, s.alpha_x, s.alpha_y, vx, vy, vz)
                mass = lobe_mass(nodes, shares, vz)
            x, y, z = wo[j, 0], wo[j, 1], wo[j, 2]
            wx, wy, wz = unit(x, y, z)
            lam = lambdas[j]
            if math.isnan(lam):
                lam = unsigned_lambda(s, x, y, z)
            result[j] = approximate_density(s, mass, vx, vy, vz, li, wx, wy, wz, lam * abs(wz))

    @compiled(error_model="numpy")
    def unit_rows(w):
        """The rows of w (m, 3) normalised (primitives.unit), a new array."""
        out = np.empty(w.shape)
        for j in range(w.shape[0]):
            out[j, 0], out[j, 1], out[j, 2] = unit(w[j, 0], w[j, 1], w[j, 2])
        return out

    @compiled(error_model="numpy")
    def finish(outcome, wi, reflect, transmit, wo, weight, lambdas):
        """wo, weight and wo's Lambda of each walk from its outcome row (walk_all): a walk that
        did not leave, or left into a lobe the parent lacks, weighs 0 (wo (0, 0, 1))."""
        for j in range(outcome.shape[0]):
            r = j if wi.shape[0] > 1 else 0
            x, y, z = outcome[j, EXIT_X], outcome[j, EXIT_Y], outcome[j, EXIT_Z]
            w = 0.0
            if math.isfinite(x):
                w = outcome[j, WEIGHT] if (reflect if (wi[r, 2] > 0.0) == (z > 0.0)
                                           else transmit) else 0.0
            else:
                x, y, z = 0.0, 0.0, 1.0
            wo[j, 0], wo[j, 1], wo[j, 2] = x, y, z
            weight[j] = w
            lambdas[j] = outcome[j, EXIT_LAMBDA]


def approximate_pdf(walk, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """RandomWalkBSDF.approximate_pdf by the kernel, wi (m, 3) with m = 1 or n, wo (n, 3)."""
    result = np.empty(wo.shape[0])
    densities(surface(walk.slopes, walk.micro), walk.share_nodes, walk.share_tables(), wi, wo,
              np.full(wo.shape[0], np.nan), result)
    return result


def sample(walk, wi: np.ndarray, u: np.ndarray,
           rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """RandomWalkBSDF.sample by the kernel: one walk from each row of wi (m, 3; one row for all,
    or n) normalised, the first event driven by u (n, 3); the density at wi as given where the
    weight is not 0."""
    n = u.shape[0]
    s = surface(walk.slopes, walk.micro)
    rules = Rules(False, False, False, 0, 1, walk.max_order or 0, 0.0, False, 0.0)
    reflect, transmit = "reflection" in walk.lobes, "transmission" in walk.lobes
    nodes, shares = walk.share_nodes, walk.share_tables()
    state = rng.integers(0, 2**64, size=4, dtype=np.uint64)  # walk_all advances it
    one = len(wi) == 1
    units, resumed = unit_rows(wi) if one else None, paths(0)
    block = min(n, BLOCK)
    outcome, lambdas, scores = np.empty((block, OUTCOMES)), np.empty(block), np.empty((block, 0))
    wo, weight, pdf = np.empty((n, 3)), np.empty(n), np.empty(n)
    for start in range(0, n, BLOCK):
        stop = min(n, start + BLOCK)
        m = stop - start
        rows = wi if one else wi[start:stop]
        rows_unit = units if one else unit_rows(rows)  # a block at a time, while in cache
        walk_all(s, rules, rows_unit, resumed, np.uint64(0), 0, state, u[start:stop],
                 NO_TARGETS, NO_LAMBDAS, scores[:m], outcome[:m])
        finish(outcome[:m], rows, reflect, transmit, wo[start:stop], weight[start:stop],
               lambdas[:m])
        densities(s, nodes, shares, rows, wo[start:stop], lambdas[:m], pdf[start:stop])
    pdf[weight == 0.0] = 0.0
    return wo, weight, pdf
