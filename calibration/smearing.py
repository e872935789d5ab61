"""What the instrument averages a BSDF over before the detector reports it: the aperture's cap
of outgoing directions and the divergent beam's cone of incoming ones (the fit's forward model
of a reading, beside the point model). Where an edge of the model (a jump or kink on a known
circle: model.optics.edges.EdgeCircles) crosses the aperture, the aperture is split along it as
the bench splits it (model.optics.quadrature.split_cap_rule), so the two agree to ~1e-5 there."""

from __future__ import annotations

import math
import threading
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from model.optics.aperture import crossing, order_for, split_order_for
from model.optics.edges import EdgeCircles
from model.optics.quadrature import cap_rule, split_cap_rule

#: Radial order over an aperture that straddles an edge of the lobe not on a known circle (a
#: model whose edges are not known, a cap too near a circle family's axis): the bench's top order
EDGE_ORDER = 40
RIM_POINTS = 24  # directions on the aperture's rim probed for an edge of such a model
#: Accuracy asked of a split aperture (model.optics.aperture.split_order_for), so the fit's model of
#: a reading across an edge follows the bench's to ~1e-5 (the data's sigma is a few 1e-4)
SPLIT_RTOL = 1e-5
BEAM_MARGIN = 3.0  # beam half-angles by which the beam's tilt may move an edge circle
#: Bytes of node-pair plans kept across calls (a fit's few pair sets, ~5 MB for Walter's 588
#: readings), the least recently used dropped beyond: a one-off dense average (synthetic data at
#: order 16) is not worth keeping
KEPT_BYTES = 1 << 27


def _rim(w: np.ndarray, half_angle_rad: float, n: int) -> np.ndarray:
    """n directions (N, n, 3) on the circle of half-angle half_angle_rad about each w (N, 3)."""
    helper = np.where(np.abs(w[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    t1 = np.cross(w, helper)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(w, t1)
    phi = 2.0 * np.pi * np.arange(n) / n
    ring = np.cos(phi)[None, :, None] * t1[:, None, :] + np.sin(phi)[None, :, None] * t2[:, None, :]
    return math.cos(half_angle_rad) * w[:, None, :] + math.sin(half_angle_rad) * ring


def model_edges(model: Any) -> EdgeCircles | None:
    """The circles where a model.bsdf model jumps or kinks (EdgeCircles, lit from air), from the
    candidate itself (its eta): a RoughDielectric's or a RoughConductor's; None for another (a
    model.bsdf.families one, a coat's eta included)."""
    if getattr(model, "family", ""):
        return None
    if hasattr(model, "eta_complex"):
        return EdgeCircles(1.0, 1.0, transmits=False)
    eta = getattr(model, "eta", None)
    return EdgeCircles(1.0, float(eta), transmits=True) if isinstance(eta, float) else None


def _alpha(model: Any) -> float | None:
    """The model's narrowest roughness, or None when it has no microfacet distribution."""
    distribution = getattr(model, "distribution", None)
    if not hasattr(distribution, "alpha_x"):
        return None
    return min(distribution.alpha_x, distribution.alpha_y)


def _cutting_family(edges: EdgeCircles, wi: np.ndarray, wo: np.ndarray, half_angle: float
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per point (N) of beam directions wi (N, K, 3) about a cap of half_angle about wo (N, 3):
    whether an edge circle crosses the cap for some beam direction; whether a family of them
    does and can be split along for all of them (quadrature.splittable's condition); the first
    such family's axes (N, K, 3) and its levels (N, K, L), those crossing no cap pushed out of
    [-1, 1] and sorted last (the bench's choice of family, model.optics.aperture, for many points
    at once)."""
    n, k = wi.shape[:2]
    crossed, chosen = np.zeros(n, bool), np.zeros(n, bool)
    axes, levels = np.zeros((n, k, 3)), np.full((n, k, 1), 2.0)
    for axis, level in edges.circles(wi.reshape(-1, 3), free_is_wo=True):
        axis, level = axis.reshape(n, k, 3), level.reshape(n, k, level.shape[-1])
        cos_t = np.clip(np.einsum("nkj,nj->nk", axis, wo), -1.0, 1.0)
        crosses = crossing(cos_t, level, half_angle)
        splits = np.all(np.abs(cos_t) <= math.cos(2.0 * half_angle), axis=1)
        crossed |= crosses.any(axis=(1, 2))
        take = ~chosen & crosses.any(axis=(1, 2)) & splits
        if take.any():
            # crossing levels first, the others at 2 (outside: a piece of zero weight)
            level = np.sort(np.where(crosses, level, 2.0), axis=-1)[..., :max(
                1, int(crosses[take].sum(axis=-1).max()))]
            width = max(levels.shape[-1], level.shape[-1])
            levels = np.pad(levels, ((0, 0), (0, 0), (0, width - levels.shape[-1])),
                            constant_values=2.0)
            level = np.pad(level, ((0, 0), (0, 0), (0, width - level.shape[-1])),
                           constant_values=2.0)
            axes[take], levels[take] = axis[take], level[take]
            chosen |= take
    return crossed, chosen, axes, levels


@dataclass(frozen=True)
class Smearing:
    """What the instrument averages the BSDF over: the detector aperture (a cap of half-angle
    aperture_deg about wo, weighted by |cos o| relative to the centre, as the detector collects
    f |cos o| dw and reduction divides by the centre's |cos o|) and the beam's divergence (a
    cone of half-angle divergence_deg about wi), each a cap rule of the given radial order.
    An aperture crossed by one of the model's edge circles (model_edges) is split along them
    (at each node of the beam's rule, as the bench does); an aperture over which a model of
    unknown edges falls to zero somewhere gets EDGE_ORDER."""

    aperture_deg: float
    aperture_order: int
    divergence_deg: float
    divergence_order: int

    def _nodes(self, w: np.ndarray, deg: float, order: int) -> tuple[np.ndarray, np.ndarray]:
        """Cap rule nodes (N, K, 3) about w (N, 3) and weights (K,) summing to 1."""
        if deg <= 0.0 or order <= 0:
            return w[:, None, :], np.ones(1)
        x, weight = cap_rule(w, math.radians(deg), order)
        return x, weight / weight.sum()

    def _product(self, wi: np.ndarray, wo: np.ndarray, order: int) -> _Runs:
        """The product rule of the beam cone and an aperture of this order at each pair, as
        runs of node pairs (the point's own order, n k p)."""
        wi_n, wi_w = self._nodes(wi, self.divergence_deg, self.divergence_order)
        wo_n, wo_w = self._nodes(wo, self.aperture_deg, order)
        shape = (len(wi), len(wi_w), len(wo_w), 3)
        # the detector collects f |cos o| dw; reduction divides by |cos o| at the centre
        cos_ratio = np.abs(wo_n[..., 2]) / np.maximum(np.abs(wo[:, None, 2]), 1e-300)
        weights = wi_w[None, :, None] * (wo_w * cos_ratio)[:, None, :]
        return _Runs(np.broadcast_to(wi_n[:, :, None, :], shape).reshape(-1, 3),
                     np.broadcast_to(wo_n[:, None, :, :], shape).reshape(-1, 3),
                     weights.ravel(), shape[1] * shape[2])

    def _edge_beam_order(self) -> int:
        """The beam rule's order where an edge crosses the aperture: the beam moves the edge
        across the aperture, whose integral varies on the aperture's scale, not the lobe's
        (a point beam is off by ~1e-4 of the peak at 0.03 deg; the bench's _beam_width)."""
        if self.divergence_deg <= 0.0:
            return 0
        return max(self.divergence_order,
                   order_for(self.divergence_deg / self.aperture_deg, SPLIT_RTOL))

    def average(self, model: Any, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        """Model BSDF (N,) averaged over the caps about each wi (N, 3) and wo (N, 3)."""
        if self.aperture_order <= 0 and self.divergence_order <= 0:
            return model.eval(wi, wo)
        pairs = (np.ascontiguousarray(wi, float).tobytes(),
                 np.ascontiguousarray(wo, float).tobytes())
        edges = model_edges(model)
        if self.aperture_deg > 0.0 and self.aperture_order > 0 and edges is not None:
            alpha = _alpha(model)
            n = split_order_for(math.radians(self.aperture_deg) / (0.34 * alpha) if alpha
                                else 0.0, SPLIT_RTOL)
            return _edge_plan(self, edges, n, EDGE_ORDER, *pairs).average(model)[0]
        plan = _product_plan(self, *pairs)
        out, f = plan.average(model)
        if self.aperture_deg <= 0.0 or self.aperture_order <= 0:
            return out
        # edges unknown: an edge is found where the model is zero on some nodes and not on
        # all, the rule's nodes stopping short of the rim, on the rim too
        lit = (f > 0).reshape(len(out), -1)
        rim = _rim(wo, math.radians(self.aperture_deg), RIM_POINTS)
        lit = np.concatenate([lit, model.eval(wi[:, None, :], rim) > 0, (out > 0)[:, None]],
                             axis=1)
        straddles = lit.any(axis=1) & ~lit.all(axis=1)
        if straddles.any():
            # an edge of the lobe inside the aperture that no split follows: a low-order rule
            # is off by up to its whole jump; the bench's top order converges algebraically
            top = _Plan.of([(np.arange(np.count_nonzero(straddles)),
                             self._product(wi[straddles], wo[straddles], EDGE_ORDER))])
            out[straddles] = top.average(model)[0]
        return out


@dataclass(frozen=True)
class _Runs:
    """Node pairs wi, wo (R L, 3) and their weights (R L,): R points' rules of L pairs each."""

    wi: np.ndarray
    wo: np.ndarray
    weights: np.ndarray
    length: int


_NO_RUNS = _Runs(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), 1)


@dataclass(frozen=True)
class _Plan:
    """Every node pair the forward model evaluates for a pair set, flat and contiguous (M, 3),
    and how they sum to each point's average: weights (M,), the first pair of each point's run
    (starts) and the point each run averages (points); fixed per pair set, so a fit's calls
    are one kernel call and one weighted sum."""

    wi: np.ndarray
    wo: np.ndarray
    weights: np.ndarray
    starts: np.ndarray
    points: np.ndarray

    @staticmethod
    def of(pieces: list[tuple[np.ndarray, _Runs]]) -> _Plan:
        """The plan of pieces (points (R,), their runs), the pieces' points together 0 ... N - 1
        in any order."""
        pieces = ([(points, runs) for points, runs in pieces if len(points)]
                  or [(np.zeros(0, np.intp), _NO_RUNS)])
        lengths = np.concatenate([np.full(len(points), runs.length) for points, runs in pieces])
        wi, wo, weights = (np.concatenate([getattr(runs, name) for _, runs in pieces])
                           for name in ("wi", "wo", "weights"))
        return _Plan(wi, wo, weights, np.cumsum(lengths) - lengths,
                     np.concatenate([points for points, _ in pieces]))

    def average(self, model: Any) -> tuple[np.ndarray, np.ndarray]:
        """(each point's weighted sum (N,), the model at the node pairs (M,))."""
        out = np.empty(len(self.points))
        if not len(self.points):
            return out, np.zeros(0)
        f = model.eval(self.wi, self.wo)
        out[self.points] = np.add.reduceat(f * self.weights, self.starts)
        return out, f

    @property
    def nbytes(self) -> int:
        """Bytes its arrays hold."""
        return sum(getattr(self, field.name).nbytes for field in fields(self))


class _Kept:
    """A plan builder's plans by their arguments, kept while they hold at most KEPT_BYTES
    together, the least recently used dropped first."""

    def __init__(self, build: Callable[..., _Plan]):
        self.build, self.plans = build, OrderedDict()
        self.__doc__ = build.__doc__
        self._lock = threading.Lock()  # lru_cache's thread safety, which this replaces

    def __call__(self, *key: Any) -> _Plan:
        with self._lock:
            plan = self.plans.pop(key, None)
            if plan is None:
                plan = self.build(*key)
            self.plans[key] = plan  # the most recent last
            while sum(kept.nbytes for kept in self.plans.values()) > KEPT_BYTES:
                self.plans.popitem(last=False)
            return plan


def _pairs(wi_bytes: bytes, wo_bytes: bytes) -> tuple[np.ndarray, np.ndarray]:
    """The pairs (N, 3) a plan is kept for, from their float64 bytes."""
    return np.frombuffer(wi_bytes).reshape(-1, 3), np.frombuffer(wo_bytes).reshape(-1, 3)


@_Kept
def _product_plan(optics: Smearing, wi_bytes: bytes, wo_bytes: bytes) -> _Plan:
    """The product rule's plan at the pairs (given as float64 bytes; kept: a fit asks for the
    same pairs at every candidate)."""
    wi, wo = _pairs(wi_bytes, wo_bytes)
    return _Plan.of([(np.arange(len(wi)), optics._product(wi, wo, optics.aperture_order))])


@_Kept
def _edge_plan(optics: Smearing, edges: EdgeCircles, n: int, edge_order: int, wi_bytes: bytes,
               wo_bytes: bytes) -> _Plan:
    """The plan at the pairs (float64 bytes) for a model of known edges: the split rule where
    an edge circle crosses the aperture, edge_order where one crosses that no split can follow,
    the product rule elsewhere (kept: a fit asks for the same pairs at every candidate alpha,
    and the rules depend only on eta and the orders)."""
    wi, wo = _pairs(wi_bytes, wo_bytes)
    where, split, straddles = _split_rule(optics, edges, n, wi, wo)
    rest = np.ones(len(wi), bool)
    rest[where] = False
    rest &= ~straddles
    return _Plan.of([(where, split),
                     (np.flatnonzero(straddles),
                      optics._product(wi[straddles], wo[straddles], edge_order)),
                     (np.flatnonzero(rest),
                      optics._product(wi[rest], wo[rest], optics.aperture_order))])


def _split_rule(optics: Smearing, edges: EdgeCircles, n: int, wi: np.ndarray, wo: np.ndarray
                ) -> tuple[np.ndarray, _Runs, np.ndarray]:
    """The split aperture rule of the points (where, M) an edge circle crosses, as runs of
    beam node x aperture node pairs (|cos o| ratio and the beam's weight included, normalised
    per beam node), and the points (N,) crossed by an edge no split can follow (an aperture
    too near the family's axis)."""
    half_angle = math.radians(optics.aperture_deg)
    # the beam's tilt moves a circle by about as much (1 / (e sin) <= 1.4 for glass lit from
    # air): only apertures within BEAM_MARGIN beam half-angles of one can be crossed
    near = np.flatnonzero(_cutting_family(edges, wi[:, None, :], wo, half_angle + BEAM_MARGIN
                                          * math.radians(optics.divergence_deg))[0])
    wi_n, wi_w = optics._nodes(wi[near], optics.divergence_deg, optics._edge_beam_order())
    k = wi_n.shape[1]
    crossed, split, axes, levels = _cutting_family(edges, wi_n, wo[near], half_angle)
    straddles = np.zeros(len(wi), bool)
    straddles[near] = crossed & ~split
    where, m = near[split], int(split.sum())
    if m == 0:
        return where, _NO_RUNS, straddles
    centers = np.repeat(wo[where], k, axis=0)
    nodes, weights = split_cap_rule(centers, half_angle, axes[split].reshape(-1, 3),
                                    levels[split].reshape(len(centers), -1), n, n)
    # the detector collects f |cos o| dw; reduction divides by |cos o| at the centre
    cos_ratio = np.abs(nodes[..., 2]) / np.maximum(np.abs(centers[:, None, 2]), 1e-300)
    weights = (weights * cos_ratio / np.sum(weights, axis=1, keepdims=True)).reshape(m, k, -1)
    p = weights.shape[-1]
    return where, _Runs(
        np.broadcast_to(wi_n[split][:, :, None, :], (m, k, p, 3)).reshape(-1, 3),
        nodes.reshape(-1, 3), (weights * wi_w[:, None]).ravel(), k * p), straddles


def aperture_average(model: Any, wi: np.ndarray, wo: np.ndarray, half_angle_deg: float,
                     order: int) -> np.ndarray:
    """The model averaged over the detector aperture (a cap about wo), or at wo if no aperture."""
    return Smearing(half_angle_deg, order, 0.0, 0).average(model, wi, wo)


def smearing_order(half_angle_deg: float, alpha: float) -> int:
    """Radial nodes of a cap rule (aperture or divergence cone): enough to resolve the narrowest
    lobe feature (a transmitted lobe is about 0.34 alpha rad wide for eta 1.5) across the cap."""
    ratio = math.radians(half_angle_deg) / (0.34 * alpha)
    if ratio < 0.02:  # the cap changes the lobe by about ratio^2 < 4e-4: a point will do
        return 0
    return int(np.clip(math.ceil(2.0 + 4.0 * ratio), 2, 12))
