"""Scattering orders >= 2 of the random walk, tabulated over outgoing directions per incidence.

What a single-scattering model leaves out is a broad, smooth lobe. HigherOrderLobe walks from
the incidence angles of a grid (INCIDENCE_NODES_DEG) and, from every walk, estimates that lobe
towards every polar angle of a column of the direction grid at once (next-event estimation
from the same paths, so a column's Monte Carlo error is smooth in theta_o), then interpolates:
deterministic, with a stated standard error per node, and far cheaper per evaluation than a
walk per pair. higher_orders_at does the same at given pairs, without a grid. Isotropic
microsurfaces only (the lobe then depends on theta_i, theta_o and phi_o - phi_i).
"""

from __future__ import annotations

import numpy as np

from sim.bsdf.multiple_scattering.keyed import keyed_walk_to_targets
from sim.bsdf.vectors import directions

#: Incidence angles (deg from the side's normal) walked; others interpolate linearly between.
INCIDENCE_NODES_DEG = np.append(np.arange(0.0, 90.0, 5.0), 89.5)
#: Grid steps (deg) of the polar angle of wo from +z (both hemispheres) and of its azimuth
#: from the plane of incidence (one side: an isotropic surface is mirror-symmetric about it).
THETA_STEP_DEG = 2.5
PHI_STEP_DEG = 15.0
#: Incidence weights below this (0.1 deg of a 5 deg step) go to the nearer node, so a divergent
#: beam's nodes about a node's incidence walk no neighbouring tables (the lobe changes by a few
#: % between nodes: the change is < 0.1 % of it).
INCIDENCE_SNAP = 0.02
#: Azimuth weights below this go to the nearer column, so an aperture's nodes a little off the
#: plane of incidence need no second column (the change is below 1 % of the difference between
#: neighbouring columns, itself a few % of f: under the tables' Monte Carlo error).
PHI_SNAP = 0.01
#: Walks per table column by default (all polar angles of the column share them).
WALKS = 1 << 14
#: Walks advanced together: BATCH_PRODUCTS // targets, within [WALK_BATCH, 16 WALK_BATCH] (a
#: function of the target count only, so one seed walks the same paths for the same count).
WALK_BATCH = 2048
BATCH_PRODUCTS = 1 << 20


def grid_directions(theta_deg: np.ndarray, phi_deg: np.ndarray) -> np.ndarray:
    """The direction grid (len(theta_deg), len(phi_deg), 3) in the frame with wi in x-z."""
    t, p = np.meshgrid(np.radians(theta_deg), np.radians(phi_deg), indexing="ij")
    return np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=-1)


def walk_to_targets(walk, wi: np.ndarray, targets: np.ndarray, walks: int,
                    rng: np.random.Generator, min_order: int = 2, covariance: bool = True,
                    keyed: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Orders >= min_order of f |cos o| from one wi (3,) towards every target (m, 3): (mean,
    standard error, covariance (m, m) of the mean, None unless asked for) over `walks`
    unguided walks of a RandomWalkBSDF, each walk scoring every target (so the errors of
    different targets are correlated). Compiled walkers use keyed.keyed_walk_to_targets
    (branch-split walks, the covariance from the first walks' correlation) unless keyed is
    False; otherwise Walker.run's walks, the covariance from every walk (m^2 per walk)."""
    if keyed and walk.walker.compiled:
        return keyed_walk_to_targets(walk.walker, wi, targets, walks, rng, min_order, covariance)
    m = len(targets)
    batch = int(np.clip(BATCH_PRODUCTS // max(m, 1), WALK_BATCH, 16 * WALK_BATCH))
    total, products, done = np.zeros(m), np.zeros((m, m) if covariance else m), 0
    while done < walks:
        k = min(batch, walks - done)
        res = walk.walker.run(np.repeat(wi[None, :], k, axis=0), rng, targets=targets,
                               min_order=min_order)
        total += res.value.sum(axis=0)
        products += res.value.T @ res.value if covariance else np.sum(res.value ** 2, axis=0)
        done += k
    mean = total / walks
    spread = products / walks - (np.outer(mean, mean) if covariance else mean * mean)
    var = (np.diag(spread) if covariance else spread) / max(walks - 1, 1)
    cov = spread / max(walks - 1, 1) if covariance else None
    return mean, np.sqrt(np.maximum(var, 0.0)), cov


def _incidence_frame(wi: np.ndarray, wo: np.ndarray) -> tuple[np.ndarray, ...]:
    """(side of wi: +1 / -1, theta_i deg from that side's normal, theta_o deg from +z,
    |phi_o - phi_i| deg) of direction pairs (n, 3): what an isotropic lobe depends on."""
    side = np.where(wi[:, 2] >= 0.0, 1, -1)
    theta_i = np.degrees(np.arccos(np.clip(np.abs(wi[:, 2]), 0.0, 1.0)))
    theta_o = np.degrees(np.arccos(np.clip(wo[:, 2], -1.0, 1.0)))
    turn = np.arctan2(wo[:, 1], wo[:, 0]) - np.arctan2(wi[:, 1], wi[:, 0])
    return side, theta_i, theta_o, np.degrees(np.abs(np.angle(np.exp(1j * turn))))


def higher_orders_at(parent, wi: np.ndarray, wo: np.ndarray, walks: int, seed: int,
                     incidence_tol_deg: float = 0.05, exact_second: bool = True,
                     covariance: bool = True
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Orders >= 2 of f (1/sr, no cosine) at the pairs (n, 3) of an isotropic surface, at the
    pairs themselves (no interpolation): (f, standard error, covariance (n, n) of f, or None
    when not asked for). With
    exact_second (dielectric and conductor facets), order 2 comes from the deterministic
    quadrature of second_order and only orders >= 3 are walked (their Monte Carlo error is a
    few times smaller than that of walked orders >= 2); the error is the walks'. Pairs whose
    incidence agrees within incidence_tol_deg share one set of `walks` walks from
    (seed, side, group), so their errors are correlated; other pairs' are independent."""
    from sim.bsdf.multiple_scattering.model import RandomWalkBSDF
    from sim.bsdf.multiple_scattering.second_order import second_order, supports

    walk = RandomWalkBSDF(parent, walks=walks, guided=False)
    exact_second = exact_second and supports(walk.walker)
    wi, wo = (np.asarray(w, np.float64).reshape(-1, 3) for w in np.broadcast_arrays(wi, wo))
    side, theta_i, theta_o, dphi = _incidence_frame(wi, wo)
    group = np.round(theta_i / (2.0 * incidence_tol_deg)).astype(np.int64)
    value, var = np.zeros(len(wi)), np.zeros(len(wi))
    cov = np.zeros((len(wi), len(wi))) if covariance else None
    for s, g in sorted(set(zip(side.tolist(), group.tolist(), strict=True))):
        rows = np.flatnonzero((side == s) & (group == g))
        theta = np.radians(np.mean(theta_i[rows]))
        start = np.array([np.sin(theta), 0.0, s * np.cos(theta)])
        t, p = np.radians(theta_o[rows]), np.radians(dphi[rows])
        targets = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=-1)
        rng = np.random.default_rng(np.random.SeedSequence([seed, s + 1, g]))
        mean, err, block = walk_to_targets(walk, start, targets, walks, rng,
                                           min_order=3 if exact_second else 2,
                                           covariance=covariance)
        if exact_second:
            mean = mean + second_order(walk.walker, start, targets)
        cos_o = np.abs(targets[:, 2])
        inverse = np.where(cos_o > 0.0, 1.0 / np.where(cos_o > 0.0, cos_o, 1.0), 0.0)
        value[rows], var[rows] = mean * inverse, (err * inverse) ** 2
        if covariance:
            cov[np.ix_(rows, rows)] = block * np.outer(inverse, inverse)
    return value, np.sqrt(var), cov


class HigherOrderLobe:
    """Orders >= 2 of a model's microsurface (Heitz 2016) tabulated over wo, built on first use.

    parent: the single-scattering model with height-correlated masking (its order 1 is the
    walk's, so the two add up to the full Smith microsurface); walks: walks per table column;
    seed: each column is walked from (seed, side, node, azimuth, hemisphere), so the
    tables are a fixed function of the parameters; theta_step_deg, phi_step_deg: the direction
    grid (divisors of 90 and 180); exact_second: order 2 by quadrature (second_order) and only
    orders >= 3 walked, for dielectric and conductor facets. A column is one azimuth and the
    polar angles of one hemisphere of wo: an in-plane scan of one lobe needs two per incidence
    (0 and 180 deg).
    """

    def __init__(self, parent, walks: int = WALKS, seed: int = 0,
                 theta_step_deg: float = THETA_STEP_DEG, phi_step_deg: float = PHI_STEP_DEG,
                 exact_second: bool = True):
        from sim.bsdf.multiple_scattering.model import RandomWalkBSDF
        from sim.bsdf.multiple_scattering.second_order import supports

        if int(walks) != walks or walks < 2:
            raise ValueError(f"walks must be an integer >= 2, got {walks!r}")
        self.walk = RandomWalkBSDF(parent, walks=int(walks), guided=False)
        if self.walk.slopes.alpha_x != self.walk.slopes.alpha_y:
            raise ValueError("HigherOrderLobe tabulates isotropic surfaces only "
                             "(alpha_x == alpha_y); use RandomWalkBSDF for anisotropic ones")
        for name, step, span in (("theta", theta_step_deg, 90.0), ("phi", phi_step_deg, 180.0)):
            if not (step > 0 and abs(span / step - round(span / step)) < 1e-9):
                raise ValueError(f"{name}_step_deg must divide {span:g}, got {step!r}")
        self.walks, self.seed = int(walks), int(seed)
        self.theta_deg = np.linspace(0.0, 180.0, round(180.0 / theta_step_deg) + 1)
        self.phi_deg = np.linspace(0.0, 180.0, round(180.0 / phi_step_deg) + 1)
        self._columns: dict[tuple[int, int, int], tuple[np.ndarray, np.ndarray]] = {}
        self.exact_second = exact_second and supports(self.walk.walker)

    def column(self, side: int, node: int, j: int, lower: bool) -> tuple[np.ndarray, np.ndarray]:
        """(f, its standard error) at the polar angles of one hemisphere of wo (theta_deg up to
        90, or from 90 with lower) and azimuth phi_deg[j] from the plane of incidence, for
        light arriving from the side's hemisphere (+1 above, -1 below) at
        INCIDENCE_NODES_DEG[node]; 0 on the horizon (f falls linearly in cos o there, as the
        escape probability does, so it interpolates better than f |cos o|)."""
        from sim.bsdf.multiple_scattering.second_order import second_order

        key = (side, node, j, lower)
        if key not in self._columns:
            theta = np.radians(INCIDENCE_NODES_DEG[node])
            wi = np.array([np.sin(theta), 0.0, side * np.cos(theta)])
            mid = len(self.theta_deg) // 2
            polar = self.theta_deg[mid:] if lower else self.theta_deg[:mid + 1]
            targets = grid_directions(polar, self.phi_deg[j:j + 1])[:, 0]
            rng = np.random.default_rng(
                np.random.SeedSequence([self.seed, side + 1, node, j, int(lower)]))
            mean, err, _ = walk_to_targets(self.walk, wi, targets, self.walks, rng,
                                           min_order=3 if self.exact_second else 2,
                                           covariance=False)
            if self.exact_second:
                mean = mean + second_order(self.walk.walker, wi, targets)
            cos_o = np.abs(targets[:, 2])
            inverse = np.where(cos_o > 1e-12, 1.0 / np.maximum(cos_o, 1e-12), 0.0)
            self._columns[key] = (mean * inverse, err * inverse)
        return self._columns[key]

    @property
    def columns_walked(self) -> int:
        """How many columns have been walked so far (each `walks` walks)."""
        return len(self._columns)

    def eval(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        """Orders >= 2 of f(wi, wo) in 1/sr, no cosine; wi, wo (..., 3) broadcast."""
        return self.estimate(wi, wo)[0]

    def _azimuth_weights(self, theta_o: np.ndarray, dphi: np.ndarray) -> list:
        """(column, weight per pair): linear in -cos(phi_o - phi_i) between neighbouring
        columns; within one polar step of a pole, between the columns 0 and 180 deg only (near
        a pole f = f_pole + theta g cos(dphi) + O(theta^2), so those two columns give it to
        first order, where the neighbouring columns would need all of them)."""
        c = -np.cos(np.radians(dphi))
        step = self.theta_deg[1] - self.theta_deg[0]
        near_pole = (theta_o < step) | (theta_o > 180.0 - step)
        last = len(self.phi_deg) - 1
        weights = dict(_linear_weights(c, -np.cos(np.radians(self.phi_deg)), PHI_SNAP))
        ends = dict(_linear_weights(c, np.array([-1.0, 1.0]), PHI_SNAP))
        out = []
        for j in sorted({*weights, 0, last}):
            w = weights.get(j, np.zeros(len(c)))
            end = ends.get(0 if j == 0 else 1, np.zeros(len(c))) if j in (0, last) else 0.0
            w = np.where(near_pole, end, w)
            if np.any(w > 0.0):
                out.append((j, w))
        return out

    def estimate(self, wi: np.ndarray, wo: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(f, its Monte Carlo standard error) of orders >= 2, interpolated from the tables:
        linear in theta_o, in cos(phi_o - phi_i) (f is even in the azimuth about the plane of
        incidence, so smooth in its cosine) and between incidence nodes; only the columns a
        pair's interpolation weights need are walked."""
        wi, wo = directions(wi, wo)
        wi, wo = np.broadcast_arrays(wi, wo)
        shape = wi.shape[:-1]
        side, theta_i, theta_o, dphi = _incidence_frame(wi.reshape(-1, 3), wo.reshape(-1, 3))
        value, var = np.zeros(len(side)), np.zeros(len(side))
        ti = theta_o / (self.theta_deg[1] - self.theta_deg[0])
        t0 = np.minimum(np.floor(ti).astype(int), len(self.theta_deg) - 2)
        a = ti - t0
        mid = len(self.theta_deg) // 2
        below = t0 >= mid  # which half-column: rows up to the horizon, or from it
        t0 = np.where(below, t0 - mid, t0)
        by_azimuth = self._azimuth_weights(theta_o, dphi)
        for node, w_node in _linear_weights(theta_i, INCIDENCE_NODES_DEG, INCIDENCE_SNAP):
            # at normal incidence the lobe does not depend on the azimuth: column 0 serves all
            for j, w_phi in by_azimuth if node else [(0, np.ones(len(side)))]:
                w = w_node * w_phi
                for s, half in ((1, False), (1, True), (-1, False), (-1, True)):
                    r = (w > 0.0) & (side == s) & (below == half)
                    if not r.any():
                        continue
                    f, err = self.column(s, node, j, half)
                    value[r] += w[r] * ((1.0 - a[r]) * f[t0[r]] + a[r] * f[t0[r] + 1])
                    var[r] += (w[r] * ((1.0 - a[r]) * err[t0[r]] + a[r] * err[t0[r] + 1])) ** 2
        return value.reshape(shape), np.sqrt(var).reshape(shape)


def _linear_weights(x: np.ndarray, nodes: np.ndarray, snap: float = 1e-9):
    """(node index, weight per point) of linear interpolation on increasing nodes (clamped),
    for the nodes with any positive weight; a point within `snap` of a step from a node gives
    that node weight 1."""
    pos = np.interp(x, nodes, np.arange(len(nodes), dtype=np.float64))
    pos = np.where(np.abs(pos - np.round(pos)) < snap, np.round(pos), pos)
    lower = np.minimum(np.floor(pos).astype(int), len(nodes) - 2)
    frac = pos - lower
    weights: dict[int, np.ndarray] = {}
    for index, weight in ((lower, 1.0 - frac), (lower + 1, frac)):
        for k in np.unique(index[weight > 0.0]):
            weights.setdefault(int(k), np.zeros(len(x)))
            weights[int(k)] += np.where(index == k, weight, 0.0)
    return sorted(weights.items())
