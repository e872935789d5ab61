"""The detector's aperture integral, convolved with the beam's divergence, to a stated accuracy.

P / Phi = mean over the beam's cone of incident directions of the integral over the aperture's
cap of g(wi, wo) d omega_o, where g is the sample's radiometric integrand. Each of the two caps
gets the product rule of model.optics.quadrature; its order follows from q = cap half-angle /
local lobe scale (rtol is split evenly between them). The rule below was calibrated on lobes of
every offset from the cap's centre (tests/bench, bench/aperture_accuracy.py): the one-point
formula has relative error about q^2 / 4, so it is used only when q^2 <= rtol (a safety factor
of 4); otherwise Gauss-Legendre order ceil(1 + d/3 + (0.7 + 0.1 d) q^0.7), d = log10(1/rtol).
Where an edge of the lobe (a jump or kink of g, on a known circle: LobeScales.edges) crosses a
cap, that cap is split along it (quadrature.split_cap_rule, order split_order_for), once per
node of the other cap, since the circle moves with it; so the edge costs no accuracy. Edges
that are not circles (a slab's transmission) or a cap too near a family's axis fall back to
the top polar order, which converges only algebraically (about 5e-3 across a jump).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from model.optics.edges import EdgeCircles
from model.optics.quadrature import cap_rule, cap_solid_angle, split_cap_rule, splittable

MAX_ORDER = 40
#: Top order of a split cap's pieces: they are smooth, so 24 resolves lobes down to 1/20 of the
#: half-angle (q = 31 at rtol 1e-3); lobe widths estimated near an edge collapse (the
#: half-vector map degenerates there) though the integrand stays smooth (order 6 is within
#: 1e-7 exactly on the end of GGX's transmitted lobe), so 40 would cost 2 x 1600 nodes for naught.
SPLIT_MAX_ORDER = 24
SAFETY = 1.5  # the BSDF's lobe scales are estimates: q is taken 1.5 times larger
Integrand = Callable[[np.ndarray, np.ndarray], np.ndarray]


class LobeScales(NamedTuple):
    """Angular scales (rad) near (wi, wo): the smooth lobe's local width in wi and wo, and the
    distance to the nearest edge (a jump or kink: the horizon, a facet seen edge-on, vertical
    facets, TIR) in wi and wo; `edges`, when they are all circles (EdgeCircles), lets the
    aperture integral split its caps along them."""

    width_i: float
    width_o: float
    edge_i: float
    edge_o: float
    edges: EdgeCircles | None = None


def order_for(q: float, rtol: float) -> int:
    """Polar Gauss order for a cap whose half-angle is q local lobe scales (0 = one point)."""
    if q * q <= rtol:
        return 0
    digits = math.log10(1.0 / rtol)
    return min(MAX_ORDER, math.ceil(1.0 + digits / 3.0 + (0.7 + 0.1 * digits) * q**0.7))


def split_order_for(q: float, rtol: float) -> int:
    """Gauss order across and along each piece of a cap split along an edge, for a cap whose
    half-angle is q local lobe scales: ceil(5 + d + (1.1 + 0.1 d) q^0.7), d = log10(1/rtol),
    calibrated like order_for on Gaussian lobes cut by circles at every offset
    (tests/bench/test_aperture_split.py). It starts higher than order_for: the pieces are
    not round, and at the horizon g's fall to zero (masking, the multiple-scattering tables) is
    not what the lobe's width describes (measured 1e-3 at order 5, 3e-7 at order 8)."""
    digits = math.log10(1.0 / rtol)
    return min(SPLIT_MAX_ORDER, math.ceil(5.0 + digits + (1.1 + 0.1 * digits) * q**0.7))


def _beam_mean(weights: np.ndarray, n_i: int) -> np.ndarray:
    """Weights of the mean over the beam cone's nodes (one node: a collimated beam)."""
    return np.ones(1) if n_i == 0 else weights / weights.sum()


def crossing(cos_t: np.ndarray, levels: np.ndarray, half_angle: float) -> np.ndarray:
    """Which edge circles {w: axis . w = level} (levels (..., L)) cross a cap of half_angle
    whose centre lies at cos_t = axis . centre (...) (a level outside (-1, 1): no circle); the
    rule the bench and the fit's smearing (calibration.smearing) choose a split by."""
    t = np.arccos(np.clip(cos_t, -1.0, 1.0))[..., None]
    return (np.abs(levels) < 1.0) & (
        np.abs(t - np.arccos(np.clip(levels, -1.0, 1.0))) < half_angle)


def _cutting_circles(edges: EdgeCircles, fixed: np.ndarray, center: np.ndarray,
                     half_angle: float, free_is_wo: bool) -> tuple[np.ndarray, np.ndarray] | None:
    """(axis (N, 3), levels (N, L)) of the first family of edge circles (one axis) that crosses
    the cap about center for some of the fixed directions (N, 3) and can be split along, with
    only its crossing levels; None when none can. A second family crossing the same cap stays
    inside a piece: the model's two families meet where its jumps vanish (GGX's vertical-facet
    jump is D(90 deg) times i.m, which is 0 on the end of the transmitted lobe; at normal
    incidence the two are the same circle)."""
    for axis, levels in edges.circles(fixed, free_is_wo):
        inside = crossing(axis @ center, levels, half_angle)
        if inside.any() and splittable(center, half_angle, axis):
            return axis, levels[:, inside.any(axis=0)]
    return None


def _split_inner(g: Integrand, edges: EdgeCircles, fixed: tuple[np.ndarray, float, int],
                 free: tuple[np.ndarray, float, int], free_is_wo: bool
                 ) -> tuple[np.ndarray, np.ndarray] | None:
    """At each node of the fixed cap's polar rule, the integral of g over the free cap split
    along the edge circles there: (the fixed rule's weights, the integrals), or None when no
    family of circles can be split along. Caps are (centre, half-angle, order)."""
    fixed_nodes, fixed_weights = cap_rule(*fixed)
    center, half_angle, n = free
    cut = _cutting_circles(edges, fixed_nodes, center, half_angle, free_is_wo)
    if cut is None:
        return None
    nodes, weights = split_cap_rule(np.broadcast_to(center, fixed_nodes.shape), half_angle,
                                    *cut, n, n)
    pairs = (fixed_nodes[:, None, :], nodes) if free_is_wo else (nodes, fixed_nodes[:, None, :])
    return fixed_weights, np.sum(g(*pairs) * weights, axis=-1)


@dataclass(frozen=True)
class ApertureIntegral:
    """Aperture of half-angle aperture_rad, beam of divergence half-angle divergence_rad
    (a uniform cone), relative accuracy rtol; `order` = (n_wi, n_wo) fixes the orders."""

    aperture_rad: float
    divergence_rad: float = 0.0
    rtol: float = 1e-3
    order: tuple[int, int] | None = None

    def __post_init__(self) -> None:
        if not (0.0 < self.aperture_rad < math.pi / 2):
            raise ValueError(f"aperture half-angle must be in (0, 90) deg, got {self.aperture_rad}")
        if not (0.0 <= self.divergence_rad < math.pi / 4):
            raise ValueError(f"divergence half-angle must be in [0, 45) deg, "
                             f"got {self.divergence_rad}")
        if not (0.0 < self.rtol < 1.0):
            raise ValueError(f"rtol must be in (0, 1), got {self.rtol}")

    @property
    def uses_scales(self) -> bool:
        """Whether integrate() reads the lobe's scales: not with both orders fixed at 0 (one
        ray each way), where neither an order nor a split is chosen."""
        return self.order != (0, 0)

    @property
    def solid_angle_sr(self) -> float:
        """The aperture's solid angle."""
        return cap_solid_angle(self.aperture_rad)

    def orders(self, scales: LobeScales) -> tuple[int, int]:
        """(n_wi, n_wo) for the lobe's scales: from q = cap half-angle / width, or MAX_ORDER
        when an edge of the lobe (a kink, where the rule converges only algebraically) lies
        inside the cap (used where the cap cannot be split along the edge)."""
        if self.order is not None:
            return self.order
        edge_in_aperture = scales.edge_o < self.aperture_rad
        n_o = (MAX_ORDER if edge_in_aperture else
               order_for(SAFETY * self.aperture_rad / scales.width_o, self.rtol / 2))
        n_i = 0
        if self.divergence_rad > 0.0:
            n_i = (MAX_ORDER if scales.edge_i < self.divergence_rad and not edge_in_aperture
                   else order_for(SAFETY * self.divergence_rad / self._beam_width(scales),
                                  self.rtol / 2))
        return n_i, n_o

    def _beam_width(self, scales: LobeScales) -> float:
        """The scale of the beam cone's integrand: with the edge inside the aperture, the beam
        averages the aperture's integral, which the cap has smoothed over its own half-angle."""
        edge_in_aperture = scales.edge_o < self.aperture_rad
        return max(scales.width_i, self.aperture_rad) if edge_in_aperture else scales.width_i

    def _split_order(self, half_angle: float, width: float, fixed: int | None) -> int:
        return fixed if fixed is not None else split_order_for(
            SAFETY * half_angle / width, self.rtol / 2)

    def integrate(self, g: Integrand, wi: np.ndarray, wo: np.ndarray,
                  scales: LobeScales) -> float:
        """Mean over the beam cone about wi of the integral over the aperture about wo of g."""
        fixed_i, fixed_o = self.order if self.order is not None else (None, None)
        beam = self.divergence_rad > 0.0
        if scales.edges is not None and scales.edge_o < self.aperture_rad and fixed_o != 0:
            n_i = 0 if not beam else fixed_i if fixed_i is not None else order_for(
                SAFETY * self.divergence_rad / self._beam_width(scales), self.rtol / 2)
            n = self._split_order(self.aperture_rad, scales.width_o, fixed_o)
            split = _split_inner(g, scales.edges, (wi, self.divergence_rad, n_i),
                                 (wo, self.aperture_rad, n), free_is_wo=True)
            if split is not None:
                wi_weights, inner = split
                return float(inner @ _beam_mean(wi_weights, n_i))
        if (scales.edges is not None and beam and scales.edge_i < self.divergence_rad
                and fixed_i != 0):
            n_o = fixed_o if fixed_o is not None else order_for(
                SAFETY * self.aperture_rad / scales.width_o, self.rtol / 2)
            n = self._split_order(self.divergence_rad, scales.width_i, fixed_i)
            split = _split_inner(g, scales.edges, (wo, self.aperture_rad, n_o),
                                 (wi, self.divergence_rad, n), free_is_wo=False)
            if split is not None:
                wo_weights, inner = split
                return float(inner @ wo_weights) / cap_solid_angle(self.divergence_rad)
        return self._product(g, wi, wo, *self.orders(scales))

    def _product(self, g: Integrand, wi: np.ndarray, wo: np.ndarray, n_i: int,
                 n_o: int) -> float:
        """The plain product of the two caps' polar rules."""
        if self.divergence_rad == 0.0:
            n_i = 0  # a collimated beam: one incident direction
        if n_i == n_o == 0:  # one ray each way: the product rule's single term, no node arrays
            return float(g(wi[None], wo[None])[0]) * self.solid_angle_sr
        wi_nodes, wi_weights = cap_rule(wi, self.divergence_rad, n_i)
        wo_nodes, wo_weights = cap_rule(wo, self.aperture_rad, n_o)
        values = g(wi_nodes[:, None, :], wo_nodes[None, :, :])
        return float(_beam_mean(wi_weights, n_i) @ values @ wo_weights)
