"""Scattering orders >= 2 of the random walk, tabulated over outgoing directions per incidence.

What a single-scattering model leaves out is a broad, smooth lobe. HigherOrderLobe walks from
the incidence angles of a grid (INCIDENCE_NODES_DEG) and, from every walk, estimates that lobe
towards every polar angle of one hemisphere of a plane of the direction grid at once
(next-event estimation from the same paths, so a column's Monte Carlo error is smooth in
theta_o), adds order 2 by quadrature, then interpolates:
deterministic, with a stated standard error per node, and far cheaper per evaluation than a
walk per pair. higher_orders_at does the same at given pairs, without a grid. Isotropic
microsurfaces only (the lobe then depends on theta_i, theta_o and phi_o - phi_i).
"""

from __future__ import annotations

import time
from collections.abc import Mapping

import numpy as np
from scipy.interpolate import PchipInterpolator

from model.bsdf.multiple_scattering.keyed import keyed_walk_from_starts, keyed_walk_to_targets
from model.bsdf.multiple_scattering.lobe_kernel import lookup
from model.bsdf.multiple_scattering.micro import MicroDielectric
from model.bsdf.multiple_scattering.plane_store import plane_store

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
#: Extra polar nodes (deg from the horizon, either side), none on it (f |cos o| is 0 there):
#: f changes fastest within a degree of it (from below by ~25 % within the last degree).
HORIZON_NODES_DEG = (1.25, 0.5, 0.02)
#: Walks per table plane by default (all its targets share them).
WALKS = 1 << 14
#: walk_both_ways: the pilot that chooses each transmitted target's direction walks this
#: share of the walks (at least PILOT_MIN_WALKS) each way.
PILOT_SHARE, PILOT_MIN_WALKS = 16, 1 << 12
#: Walks advanced together: BATCH_PRODUCTS // targets, within [WALK_BATCH, 16 WALK_BATCH] (a
#: function of the target count only, so one seed walks the same paths for the same count).
WALK_BATCH = 2048
BATCH_PRODUCTS = 1 << 20
#: HigherOrderLobe.walk_seconds times a plane's walks at this many and twice as many (both
#: past the pilot's floor, PILOT_SHARE * PILOT_MIN_WALKS, so the cost grows linearly between).
CALIBRATION_WALKS = 1 << 16


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


def walk_both_ways(walk, wi: np.ndarray, targets: np.ndarray, walks: int,
                   rng: np.random.Generator, min_order: int = 2, covariance: bool = True
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """walk_to_targets, with the targets across a dielectric (transmitted) walked the other
    way where that is better: keyed walks from them towards wi shared by them
    (keyed.keyed_walk_from_starts), f(wi, wo) = f(wo, wi) (n_o / n_i)^2 by reciprocity. A
    pilot of walks // PILOT_SHARE walks each way (at least PILOT_MIN_WALKS), not used in the
    result (so the choice adds no bias), picks each target's way by the smaller standard
    error. Conductors, wi on the horizon and walkers without kernels walk forward only."""
    targets = np.asarray(targets, np.float64).reshape(-1, 3)
    side = 1.0 if wi[2] >= 0.0 else -1.0
    across = np.flatnonzero(targets[:, 2] * side < 0.0)
    micro = walk.walker.micro
    if not (len(across) and wi[2] != 0.0 and walk.walker.compiled
            and isinstance(micro, MicroDielectric)):
        return walk_to_targets(walk, wi, targets, walks, rng, min_order, covariance)
    ratio = micro.eta ** 2 if side > 0.0 else micro.eta ** -2  # (n_o / n_i)^2
    scale = ratio * np.abs(targets[:, 2]) / abs(wi[2])

    def forward(rows: np.ndarray, n: int, cov: bool
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        return walk_to_targets(walk, wi, targets[rows], n, rng, min_order, cov)

    def reverse(rows: np.ndarray, n: int, cov: bool
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        back, err, block = keyed_walk_from_starts(walk.walker, targets[rows], wi, n, rng,
                                                  min_order, cov)
        s = scale[rows]
        return back * s, err * s, block * np.outer(s, s) if cov else None

    pilot = max(walks // PILOT_SHARE, PILOT_MIN_WALKS)
    fwd_err = forward(across, pilot, False)[1]
    back = across[reverse(across, pilot, False)[1] < fwd_err]
    ahead = np.setdiff1d(np.arange(len(targets)), back)
    mean, err = np.zeros(len(targets)), np.zeros(len(targets))
    cov = np.zeros((len(targets), len(targets))) if covariance else None
    for rows, way in ((ahead, forward), (back, reverse)):
        if len(rows):
            mean[rows], err[rows], block = way(rows, walks, covariance)
            if covariance:
                cov[np.ix_(rows, rows)] = block
    return mean, err, cov


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
                     covariance: bool = True, both_ways: bool = True, stream: int = 0
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Orders >= 2 of f (1/sr, no cosine) at the pairs (n, 3) of an isotropic surface, at the
    pairs themselves (no interpolation): (f, standard error, covariance (n, n) of f, or None
    when not asked for). With
    exact_second (dielectric and conductor facets), order 2 comes from the deterministic
    quadrature of second_order and only orders >= 3 are walked (their Monte Carlo error is a
    few times smaller than that of walked orders >= 2); the error is the walks'. Pairs whose
    incidence rounds to the same multiple of 2 incidence_tol_deg share one set of `walks` walks
    from (seed, side, group) at that incidence, so their errors are correlated; other pairs' are
    independent. Forward walks score each target on its own, so with both_ways False a pair's
    value does not depend on the other pairs of the call; both ways, a reverse walk's starts
    share its walks (keyed_walk_from_starts), so it does at the level of its error. Pairs
    the isotropic lobe cannot tell apart (the same theta_o and |phi_o - phi_i|; the same theta_o
    in the group at normal incidence, taken as exactly normal) are computed once. both_ways
    walks transmitted pairs in reverse (walk_both_ways), else all forward (walk_to_targets).
    stream > 0 draws walks independent of stream 0's (the walks of the same seed before
    streams were offered) for the same seed: a second estimate to average with the first."""
    from model.bsdf.multiple_scattering.model import RandomWalkBSDF
    from model.bsdf.multiple_scattering.second_order import second_order, supports

    walk = RandomWalkBSDF(parent, walks=walks, guided=False)
    exact_second = exact_second and supports(walk.walker)
    wi, wo = (np.asarray(w, np.float64).reshape(-1, 3) for w in np.broadcast_arrays(wi, wo))
    side, theta_i, theta_o, dphi = _incidence_frame(wi, wo)
    group = np.round(theta_i / (2.0 * incidence_tol_deg)).astype(np.int64)
    value, var = np.zeros(len(wi)), np.zeros(len(wi))
    cov = np.zeros((len(wi), len(wi))) if covariance else None
    for s, g in sorted(set(zip(side.tolist(), group.tolist(), strict=True))):
        rows = np.flatnonzero((side == s) & (group == g))
        theta = np.radians(2.0 * incidence_tol_deg * g)  # the group's, whoever is in it
        start = np.array([np.sin(theta), 0.0, s * np.cos(theta)])
        azimuth = dphi[rows] if g else np.zeros(len(rows))  # none at normal incidence
        targets, index = _distinct_targets(theta_o[rows], azimuth)
        rng = np.random.default_rng(np.random.SeedSequence(
            [seed, s + 1, g] + ([stream] if stream else [])))
        mean, err, block = (walk_both_ways if both_ways else walk_to_targets)(
            walk, start, targets, walks, rng, min_order=3 if exact_second else 2,
            covariance=covariance)
        if exact_second:
            mean = mean + second_order(walk.walker, start, targets)
        cos_o = np.abs(targets[index, 2])
        inverse = np.where(cos_o > 0.0, 1.0 / np.where(cos_o > 0.0, cos_o, 1.0), 0.0)
        value[rows], var[rows] = mean[index] * inverse, (err[index] * inverse) ** 2
        if covariance:
            cov[np.ix_(rows, rows)] = block[np.ix_(index, index)] * np.outer(inverse, inverse)
    return value, np.sqrt(var), cov


def _distinct_targets(theta_o_deg: np.ndarray, dphi_deg: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray]:
    """(distinct target directions (k, 3) in the incidence frame, index (n,) of each pair's):
    pairs with the same theta_o and |phi_o - phi_i| (mirror images about the plane of
    incidence, or any azimuth at normal incidence, where dphi is passed as 0) see the same
    lobe, so they are walked and integrated once and get the same value."""
    key = np.round(np.stack([theta_o_deg, dphi_deg], axis=-1), 9)
    distinct, index = np.unique(key, axis=0, return_inverse=True)
    t, p = np.radians(distinct[:, 0]), np.radians(distinct[:, 1])
    targets = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=-1)
    return targets, index.reshape(-1)


class HigherOrderLobe:
    """Orders >= 2 of a model's microsurface (Heitz 2016) tabulated over wo, built on first use.

    parent: the single-scattering model with height-correlated masking (its order 1 is the
    walk's, so the two add up to the full Smith microsurface); walks: walks per build; seed:
    each build is walked from (seed, side, node, plane, hemisphere), so the tables are a fixed
    function of the parameters; theta_step_deg, phi_step_deg: the direction grid (divisors of
    90 and 180); exact_second: order 2 by quadrature (second_order) and only orders >= 3
    walked, for dielectric and conductor facets. A column is one azimuth phi_deg[j] from the
    plane of incidence over all polar angles of wo; a plane through the normal holds columns j
    and last - j, whose targets in one hemisphere of wo one walk set and one second_order call
    build together: an in-plane scan of one lobe (azimuths 0 and 180) is one build.
    cache_as: the parent's parameters (whatever sets its values), under which each build is
    kept on disk with the lobe's own walks, seed and grid (plane_store) and read back by later
    lobes; None: in memory only.
    """

    def __init__(self, parent, walks: int = WALKS, seed: int = 0,
                 theta_step_deg: float = THETA_STEP_DEG, phi_step_deg: float = PHI_STEP_DEG,
                 exact_second: bool = True, cache_as: Mapping[str, object] | None = None):
        from model.bsdf.multiple_scattering.model import RandomWalkBSDF
        from model.bsdf.multiple_scattering.second_order import supports

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
        self.exact_second = exact_second and supports(self.walk.walker)
        self.theta_step = float(theta_step_deg)
        self.store = None if cache_as is None else plane_store({
            "parent": dict(cache_as), "model": type(parent).__name__, "walks": self.walks,
            "seed": self.seed, "theta_step_deg": self.theta_step,
            "phi_step_deg": float(phi_step_deg), "exact_second": bool(self.exact_second)})
        self.phi_deg = np.linspace(0.0, 180.0, round(180.0 / phi_step_deg) + 1)
        grid = np.linspace(0.0, 90.0, round(90.0 / theta_step_deg) + 1)[:-1]
        near = 90.0 - np.asarray(HORIZON_NODES_DEG)
        #: polar nodes (deg from +z) of the upper half (up to the horizon) and the lower one
        self.upper_deg = np.unique(np.concatenate([grid, near[near > grid[-1]]]))
        self.lower_deg = 180.0 - self.upper_deg[::-1]
        self.polar_deg = np.concatenate([self.upper_deg, self.lower_deg])
        last = len(self.phi_deg) - 1
        self._plane_of = np.minimum(np.arange(last + 1), last - np.arange(last + 1))
        shape = (2, len(INCIDENCE_NODES_DEG), last + 1, len(self.polar_deg))
        self._f2, self._d2, self._f3, self._d3, self._e3 = (np.zeros(shape) for _ in range(5))
        self._built = np.zeros((2, len(INCIDENCE_NODES_DEG), last // 2 + 1, 2), dtype=np.bool_)
        self._column_cos = -np.cos(np.radians(self.phi_deg))

    def build(self, side: int, node: int, plane: int, lower: bool, walk: bool = True) -> bool:
        """Walk and integrate one hemisphere of wo (lower: below the horizon) in one plane
        through the normal, i.e. columns plane and last - plane (column 0 alone at normal
        incidence, where the lobe does not depend on the azimuth), for light arriving from the
        side's hemisphere (+1 above, -1 below) at INCIDENCE_NODES_DEG[node]: one walk set
        scoring every target and one second_order call for all of them; read from the store
        instead where it holds the build. walk False: only read it from the store. Returns
        whether the plane is built."""
        columns = self._columns(node, plane)
        half = self._hemisphere(lower)
        s = 0 if side > 0 else 1
        address = (s, node, plane, int(lower))
        shape = (5, len(columns), len(self.polar_deg[half]))
        built = None if self.store is None else self.store.load(address, shape)
        if built is None and not walk:
            return False
        if built is None:
            built = self._walk_plane(side, node, plane, lower, columns)
            if self.store is not None:
                self.store.save(address, built)
        for m, j in enumerate(columns):
            for table, part in zip((self._f2, self._d2, self._f3, self._d3, self._e3), built,
                                   strict=True):
                table[s, node, j, half] = part[m]
        self._built[address] = True
        return True

    def build_at(self, address: tuple[int, int, int, int], walk: bool = True) -> bool:
        """build by a plane's address (side index 0 above / 1 below, node, plane, lower), as
        parts reports the planes it misses."""
        s, node, plane, lower = address
        return self.build(1 if s == 0 else -1, node, plane, bool(lower), walk)

    def _columns(self, node: int, plane: int) -> list[int]:
        """The columns a plane holds: plane and last - plane (one at normal incidence)."""
        last = len(self.phi_deg) - 1
        return [plane] if node == 0 or plane == last - plane else [plane, last - plane]

    def walk_seconds(self, address: tuple[int, int, int, int]) -> float:
        """Seconds walking one plane (build_at's address) with this lobe's walks takes on this
        machine now, timed from CALIBRATION_WALKS walks and twice as many (their difference
        leaves out the plane's fixed cost: order 2's quadrature), without building it."""
        s, node, plane, lower = address
        side, columns = 1 if s == 0 else -1, self._columns(node, plane)
        seconds = []
        for walks in (2, CALIBRATION_WALKS, 2 * CALIBRATION_WALKS):  # 2: compile the kernels
            start = time.perf_counter()
            self._walk_plane(side, node, plane, bool(lower), columns, walks)
            seconds.append(time.perf_counter() - start)
        per_walk = max(seconds[2] - seconds[1], 0.0) / CALIBRATION_WALKS
        return max(seconds[1] - per_walk * CALIBRATION_WALKS, 0.0) + per_walk * self.walks

    def _hemisphere(self, lower: bool) -> slice:
        """The polar nodes (of polar_deg) above the horizon, or below it."""
        split = len(self.upper_deg)
        return slice(split, None) if lower else slice(0, split)

    def _walk_plane(self, side: int, node: int, plane: int, lower: bool, columns: list[int],
                    walks: int | None = None) -> np.ndarray:
        """build's walks (the lobe's, unless `walks` says how many): (order 2, its theta_o
        slope, orders >= 3, their slope, their standard error) of f over the hemisphere's
        polar nodes, per column: (5, columns, nodes)."""
        from model.bsdf.multiple_scattering.second_order import second_order

        theta = np.radians(INCIDENCE_NODES_DEG[node])
        wi = np.array([np.sin(theta), 0.0, side * np.cos(theta)])
        half = self._hemisphere(lower)
        # column last - plane at azimuth 180 - phi is, mirrored about the plane of incidence,
        # the far side of the plane at phi; the poles are moved into that plane by 1e-6 deg so
        # second_order sees one plane
        polar = np.radians(np.clip(self.polar_deg[half], 1e-6, 180.0 - 1e-6))
        far = np.array(columns) != plane
        azimuth = np.radians(np.repeat(self.phi_deg[plane] + 180.0 * far, len(polar)))
        t = np.tile(polar, len(columns))
        targets = np.stack([np.sin(t) * np.cos(azimuth), np.sin(t) * np.sin(azimuth),
                            np.cos(t)], axis=-1)
        rng = np.random.default_rng(
            np.random.SeedSequence([self.seed, side + 1, node, plane, int(lower)]))
        mean, err, _ = walk_both_ways(self.walk, wi, targets, walks or self.walks, rng,
                                      min_order=3 if self.exact_second else 2,
                                      covariance=False)
        second = second_order(self.walk.walker, wi, targets) if self.exact_second else 0.0 * mean
        inverse = 1.0 / np.abs(targets[:, 2])  # no target on the horizon
        out = np.empty((5, len(columns), len(polar)))
        for m in range(len(columns)):
            part = slice(m * len(polar), (m + 1) * len(polar))
            for row, f in ((0, second[part] * inverse[part]), (2, mean[part] * inverse[part])):
                out[row, m] = f
                with np.errstate(over="ignore"):  # secants near 1e-300: their slope is 0
                    out[row + 1, m] = PchipInterpolator(self.polar_deg[half], f).derivative()(
                        self.polar_deg[half])
            out[4, m] = err[part] * inverse[part]
        return out

    def column(self, side: int, node: int, j: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(order 2, orders >= 3, their standard error) of f at polar_deg, azimuth phi_deg[j],
        for light arriving from the side's hemisphere at INCIDENCE_NODES_DEG[node] (at normal
        incidence every azimuth's is column 0's: the lobe does not depend on it there)."""
        j = 0 if node == 0 else j
        s, plane = (0 if side > 0 else 1), int(self._plane_of[j])
        for lower in (False, True):
            if not self._built[s, node, plane, int(lower)]:
                self.build(side, node, plane, lower)
        return self._f2[s, node, j], self._f3[s, node, j], self._e3[s, node, j]

    @property
    def planes_built(self) -> int:
        """How many hemispheres of a plane have been built so far (each `walks` walks)."""
        return int(self._built.sum())

    def eval(self, wi: np.ndarray, wo: np.ndarray, missing: set | None = None) -> np.ndarray:
        """Orders >= 2 of f(wi, wo) in 1/sr, no cosine; wi, wo (..., 3) broadcast."""
        return self.estimate(wi, wo, missing)[0]

    def estimate(self, wi: np.ndarray, wo: np.ndarray, missing: set | None = None
                 ) -> tuple[np.ndarray, np.ndarray]:
        """(f, its Monte Carlo standard error) of orders >= 2, interpolated from the tables."""
        second, higher, err = self.parts(wi, wo, missing)
        return second + higher, err

    def parts(self, wi: np.ndarray, wo: np.ndarray, missing: set | None = None
              ) -> tuple[np.ndarray, ...]:
        """(order 2, orders >= 3, the standard error of orders >= 3) of f at wi, wo (..., 3);
        without exact_second order 2 is 0 and walked with the rest. Both parts cubic (PCHIP) in
        theta_o, the error linearly, all linear in cos(phi_o - phi_i)
        (f is even in the azimuth about the plane of incidence, so smooth in its cosine) and
        between incidence nodes; within one polar step of a pole between the columns 0 and 180
        deg only (f = f_pole + theta g cos(dphi) + O(theta^2) there). Only the planes a pair's
        weights need are built; with a `missing` set, none: their addresses (as build_at takes
        them) are added to it and their share is left out of the values."""
        wi, wo = np.asarray(wi, dtype=np.float64), np.asarray(wo, dtype=np.float64)
        shape = np.broadcast_shapes(wi.shape, wo.shape)
        flat_i, flat_o = (np.ascontiguousarray(np.broadcast_to(w, shape)).reshape(-1, 3)
                          for w in (wi, wo))
        shape = shape[:-1]
        out = np.empty((3, len(flat_i)))
        rows = np.empty((4 * len(flat_i), 4), dtype=np.int64)
        while True:
            found = lookup(flat_i, flat_o, INCIDENCE_NODES_DEG, INCIDENCE_SNAP, self._column_cos,
                           PHI_SNAP, self.theta_step, self.upper_deg, self.lower_deg, self._f2,
                           self._d2, self._f3, self._d3, self._e3, self._built, self._plane_of,
                           out[0], out[1], out[2], rows)
            needed = set(map(tuple, rows[:found].tolist()))
            if missing is not None:
                missing |= needed
            if not found or missing is not None:
                break
            for address in sorted(needed):
                self.build_at(address)
        return out[0].reshape(shape), out[1].reshape(shape), np.sqrt(out[2]).reshape(shape)
