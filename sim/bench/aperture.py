"""The detector's aperture integral, convolved with the beam's divergence, to a stated accuracy.

P / Phi = mean over the beam's cone of incident directions of the integral over the aperture's
cap of g(wi, wo) d omega_o, where g is the sample's radiometric integrand. Each of the two caps
gets the product rule of sim.bench.quadrature; its order follows from q = cap half-angle /
local lobe scale (rtol is split evenly between them). The rule below was calibrated on lobes of
every offset from the cap's centre (tests/bench, bench/aperture_accuracy.py): the one-point
formula has relative error about q^2 / 4, so it is used only when q^2 <= rtol (a safety factor
of 4); otherwise Gauss-Legendre order ceil(1 + d/3 + (0.7 + 0.1 d) q^0.7), d = log10(1/rtol).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from sim.bench.quadrature import cap_rule, cap_solid_angle
from sim.bench.sample import LobeScales

MAX_ORDER = 40
SAFETY = 1.5  # the BSDF's lobe scales are estimates: q is taken 1.5 times larger
Integrand = Callable[[np.ndarray, np.ndarray], np.ndarray]


def order_for(q: float, rtol: float) -> int:
    """Polar Gauss order for a cap whose half-angle is q local lobe scales (0 = one point)."""
    if q * q <= rtol:
        return 0
    digits = math.log10(1.0 / rtol)
    return min(MAX_ORDER, math.ceil(1.0 + digits / 3.0 + (0.7 + 0.1 * digits) * q**0.7))


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
    def solid_angle_sr(self) -> float:
        """The aperture's solid angle."""
        return cap_solid_angle(self.aperture_rad)

    def orders(self, scales: LobeScales) -> tuple[int, int]:
        """(n_wi, n_wo) for the lobe's scales: from q = cap half-angle / width, or MAX_ORDER
        when an edge of the lobe (a kink, where the rule converges only algebraically) lies
        inside the cap."""
        if self.order is not None:
            return self.order
        edge_in_aperture = scales.edge_o < self.aperture_rad
        n_o = (MAX_ORDER if edge_in_aperture else
               order_for(SAFETY * self.aperture_rad / scales.width_o, self.rtol / 2))
        n_i = 0
        if self.divergence_rad > 0.0:
            # with the edge inside the aperture, the beam averages the aperture's integral,
            # which the cap has smoothed over its own half-angle: no kink left for the beam
            width_i = max(scales.width_i, self.aperture_rad) if edge_in_aperture else \
                scales.width_i
            n_i = (MAX_ORDER if scales.edge_i < self.divergence_rad and not edge_in_aperture
                   else order_for(SAFETY * self.divergence_rad / width_i, self.rtol / 2))
        return n_i, n_o

    def integrate(self, g: Integrand, wi: np.ndarray, wo: np.ndarray,
                  scales: LobeScales) -> float:
        """Mean over the beam cone about wi of the integral over the aperture about wo of g."""
        n_i, n_o = self.orders(scales)
        if self.divergence_rad == 0.0:
            n_i = 0  # a collimated beam: one incident direction
        wi_nodes, wi_weights = cap_rule(wi, self.divergence_rad, n_i)
        wo_nodes, wo_weights = cap_rule(wo, self.aperture_rad, n_o)
        values = g(wi_nodes[:, None, :], wo_nodes[None, :, :])
        beam_mean = np.ones(1) if n_i == 0 else wi_weights / wi_weights.sum()
        return float(beam_mean @ values @ wo_weights)
