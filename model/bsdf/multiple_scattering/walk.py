"""Vectorised random walk on the Smith microsurface (Heitz, Hanika, d'Eon, Dachsbacher 2016).

The microsurface is a random medium: a ray travelling along d from a point whose height has
CDF value u = C1(h) meets the surface again at u' with u'/u = exp(E / Lambda(d)), E ~ Exp(1)
(survival (C1(h0)/C1(h))^Lambda upward, (C1(h)/C1(h0))^(1+Lambda(-d)) downward), and leaves
when u' >= 1, which happens with probability G1 = u^Lambda(d). The walk is carried out in
log u (and log(1 - u) for the mirrored world below a dielectric), so it is exact at both tails
for any height distribution; the Smith BSDF does not depend on P1, heights are only reported.

All walks of a batch advance together (one numpy step per scattering order, on the walks still
alive); next-event estimation adds, at each scattering event, the phase function towards wo
times the probability G1 that wo escapes from there.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from model.bsdf.distributions import WALKABLE, Distribution
from model.bsdf.multiple_scattering import nee_kernel, walk_kernel
from model.bsdf.multiple_scattering.guiding import guided_scatter
from model.bsdf.multiple_scattering.heights import log1mexp

#: Weight below which an evaluating walk plays Russian roulette (survivors carry this weight).
ROULETTE = 0.1


def walkable(distribution: Distribution) -> Distribution:
    """The distribution, if the walk can walk on it (Distribution.multiple_scattering, one
    alpha or one (alpha_x, alpha_y) pair); else a ValueError saying why."""
    if not distribution.multiple_scattering:
        raise ValueError(
            "multiple scattering needs a Smith slope distribution "
            f"{' or '.join(repr(name) for name in WALKABLE)}, got {distribution.name!r}")
    if np.ndim(distribution.alpha_x) or np.ndim(distribution.alpha_y):
        raise ValueError("multiple scattering needs one scalar alpha (or alpha_x, alpha_y)")
    return distribution


def flip(w: np.ndarray) -> np.ndarray:
    """Mirror a direction through the mean plane (z -> -z): the frame of the world below."""
    return w * np.array([1.0, 1.0, -1.0])


@dataclass
class WalkResult:
    """Per-walk outputs of a batch: NEE sums, exit direction and weight, truncation, heights."""

    value: np.ndarray  # (n,) sum of NEE contributions (f |cos o| estimate); zeros when sampling
    exit_direction: np.ndarray  # (n, 3) world direction the walk left along (nan if it did not)
    weight: np.ndarray  # (n,) throughput when leaving (0 if it did not leave)
    truncated: np.ndarray  # (n,) energy still inside the surface when the order cap stopped it
    orders: np.ndarray  # (n,) scattering events of the walk
    first_log_cdf: np.ndarray  # (n,) log C1(h) of the first scattering event (nan if none)


class Walker:
    """Runs batches of walks for one slope distribution and one micro-BSDF; compiled: by
    walk_kernel where it covers the walk (nee_kernel.supports), else by numpy (the reference)."""

    def __init__(self, slopes: Distribution, micro, guided: bool = True, compiled: bool = True):
        self.slopes = slopes
        self.micro = micro
        self.guided = guided
        self.compiled = compiled and nee_kernel.supports(slopes, micro)

    def _escape_probability(self, d: np.ndarray, log_u: np.ndarray) -> np.ndarray:
        """G1 = u^Lambda(d) of leaving from log C1 = log_u along local direction d."""
        lam = self.slopes.signed_lambda(d)
        with np.errstate(invalid="ignore", over="ignore"):
            g = np.exp(lam * log_u)
        return np.where(lam <= 0.0, np.where(lam == 0.0, 1.0, 0.0), np.nan_to_num(g))

    def run(
        self,
        wi: np.ndarray,
        rng: np.random.Generator,
        wo: np.ndarray | None = None,
        *,
        order: int | None = None,
        max_order: int | None = None,
        unit: bool = False,
        u_first: np.ndarray | None = None,
        targets: np.ndarray | None = None,
        min_order: int = 1,
    ) -> WalkResult:
        """Walk once from each row of wi (n, 3); with wo, accumulate NEE towards wo (n, 3).

        targets (m, 3), instead of wo: accumulate NEE from every walk towards every target
        (value (n, m)); the path is then independent of the targets (no guiding), so one walk
        serves them all. min_order: count only orders >= min_order.
        order: count only that scattering order (the walk stops after it); max_order: stop after
        that many events and report the energy still inside; unit: direction density instead of
        energy; u_first (n, 3): uniforms for the first event (height, normal), for stratification.
        When evaluating (wo given) every step is forced to hit the surface, the walk's weight
        taking the hit probability 1 - G1; this bounds the NEE weight D / A(w_in) of rare hits
        along nearly vertical upward rays (the analog walk's heavy tail), and Russian roulette
        ends the walks, played after an event's NEE is scored and before it scatters (so the
        NEE that follows a guided step keeps its exact weight, and an ended event costs no
        scattering); the next direction is drawn by guided_scatter (phase function or
        backwards from wo, one-sample MIS). Sampling (no wo) runs the analog walk, which exits.
        """
        if self.compiled:
            return WalkResult(*walk_kernel.run(self, wi, rng, wo, order, max_order, unit,
                                               u_first, targets, min_order, ROULETTE))
        n = wi.shape[0]
        slopes, micro = self.slopes, self.micro
        outside = wi[:, 2] > 0.0
        d = -np.where(outside[:, None], wi, flip(wi))
        log_u = np.where(outside, 0.0, -np.inf)  # log C1(h): h = +inf above, -inf below
        log_v = np.where(outside, -np.inf, 0.0)  # log(1 - C1(h))
        beta = np.ones(n)
        alive = micro.transmits | outside
        value = np.zeros(n) if targets is None else np.zeros((n, len(targets)))
        exit_dir = np.full((n, 3), np.nan)
        weight = np.zeros(n)
        truncated = np.zeros(n)
        orders = np.zeros(n, dtype=np.int64)
        first = np.full(n, np.nan)
        idx = np.flatnonzero(alive)
        forced = wo is not None or targets is not None
        k = 0
        while idx.size:
            k += 1
            out = outside[idx]
            dk = d[idx]
            if k == 1 and u_first is not None:
                u = u_first[idx].T
            else:
                u = rng.random((3, idx.size))
            lam = slopes.signed_lambda(dk)
            cur = np.where(out, log_u[idx], log_v[idx])
            if forced:  # hit for sure, weighted by the hit probability 1 - u^Lambda
                with np.errstate(invalid="ignore", over="ignore"):
                    p_hit = np.nan_to_num(np.where(lam > 0.0, -np.expm1(lam * cur), 1.0), nan=1.0)
                beta[idx] *= p_hit
                e = -np.log1p(-u[0] * p_hit)
            else:
                e = -np.log1p(-u[0])
            with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
                new = cur + np.where(lam == 0.0, np.inf, e / lam)
            leaves = ~(new < 0.0)
            if leaves.any() and not forced:
                gone = idx[leaves]
                exit_dir[gone] = np.where(out[leaves, None], dk[leaves], flip(dk[leaves]))
                weight[gone] = beta[gone]
            keep = ~leaves
            idx, out, dk, new, u = idx[keep], out[keep], dk[keep], new[keep], u[:, keep]
            if not idx.size:
                break
            other = log1mexp(new)
            log_u[idx] = np.where(out, new, other)
            log_v[idx] = np.where(out, other, new)
            orders[idx] = k
            if k == 1:
                first[idx] = log_u[idx]
            w_in = -dk
            m = slopes.sample_visible_sphere(w_in, u[1], u[2])
            counted = k >= min_order and (order is None or order == k)
            if wo is not None and counted:
                value[idx] += beta[idx] * self._next_event(w_in, m, out, wo[idx], new, other, unit)
            elif targets is not None and counted:
                value[idx] += beta[idx, None] * self.next_event_all(w_in, m, out, targets, new,
                                                                    other, unit)
            if order is not None and k >= order:
                break
            if forced:  # Russian roulette on low weights, before scattering (unbiased)
                b = beta[idx]
                low = b < ROULETTE
                lives = ~low | (rng.random(idx.size) * ROULETTE < b)
                beta[idx] = np.where(low, np.where(lives, ROULETTE, 0.0), b)
                idx, out, w_in, m = idx[lives], out[lives], w_in[lives], m[lives]
                if not idx.size:
                    break
            scattered = micro.scatter(slopes, w_in, m, out, rng.random((2, idx.size)), unit)
            if wo is not None and self.guided and micro.guidable:
                scattered = guided_scatter(slopes, micro, w_in, m, out, wo[idx],
                                           rng.random((4, idx.size)), unit, scattered)
            w_next, factor, crossed = scattered
            beta[idx] *= factor
            outside[idx] = out ^ crossed
            d[idx] = np.where(crossed[:, None], flip(w_next), w_next)
            if max_order is not None and k >= max_order:
                side_log = np.where(outside[idx], log_u[idx], log_v[idx])
                hit = 1.0 - self._escape_probability(d[idx], side_log)
                truncated[idx] = beta[idx] * hit
                break
            idx = idx[beta[idx] > 0.0]
        return WalkResult(value, exit_dir, weight, truncated, orders, first)

    def next_event_all(self, w_in: np.ndarray, m: np.ndarray, out: np.ndarray,
                       targets: np.ndarray, log_here: np.ndarray, log_there: np.ndarray,
                       unit: bool, compiled: bool = True) -> np.ndarray:
        """Phase function x escape probability from each of n events (local w_in, facet m,
        side out, log CDFs here and across) towards each of m world targets: (n, m); public
        for second_order; compiled (nee_kernel) for dielectric and conductor facets unless
        asked not to (then numpy, the reference)."""
        if compiled and nee_kernel.supports(self.slopes, self.micro):
            return nee_kernel.compiled_next_event_all(self.slopes, self.micro, w_in, out,
                                                      targets, log_here, log_there, unit)
        n, k = len(w_in), len(targets)
        each = np.repeat(np.arange(n), k)
        flat = self._next_event(w_in[each], m[each], out[each], np.tile(targets, (n, 1)),
                                log_here[each], log_there[each], unit)
        return flat.reshape(n, k)

    def _next_event(self, w_in, m, out, wo, log_here, log_there, unit) -> np.ndarray:
        """Phase function towards wo times the probability that wo escapes from this event."""
        slopes, micro = self.slopes, self.micro
        wl = np.where(out[:, None], wo, flip(wo))  # wo in the local frame of this side
        same = wl[:, 2] > 0.0
        result = np.zeros(out.shape)
        if same.any():
            s = same
            phase = micro.phase_reflect(slopes, w_in[s], wl[s], out[s], m[s], unit)
            result[s] = phase * self._escape_probability(wl[s], log_here[s])
        if micro.transmits and (~same).any():
            s = ~same
            phase = micro.phase_transmit(slopes, w_in[s], wl[s], out[s], unit)
            result[s] = phase * self._escape_probability(flip(wl[s]), log_there[s])
        return result
