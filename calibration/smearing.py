"""What the instrument averages a BSDF over before the detector reports it: the aperture's cap
of outgoing directions and the divergent beam's cone of incoming ones (the fit's forward model
of a reading, beside the point model)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np


@dataclass(frozen=True)
class Smearing:
    """What the instrument averages the BSDF over: the detector aperture (a cap of half-angle
    aperture_deg about wo, weighted by |cos o| relative to the centre, as the detector collects
    f |cos o| dw and reduction divides by the centre's |cos o|) and the beam's divergence (a
    cone of half-angle divergence_deg about wi), each a cap rule of the given radial order."""

    aperture_deg: float
    aperture_order: int
    divergence_deg: float
    divergence_order: int

    def average(self, model: Any, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        """Model BSDF (N,) averaged over the caps about each wi (N, 3) and wo (N, 3)."""
        if self.aperture_order <= 0 and self.divergence_order <= 0:
            return model.eval(wi, wo)
        from sim.bench.quadrature import cap_rule

        def nodes(w: np.ndarray, deg: float, order: int) -> tuple[np.ndarray, np.ndarray]:
            if deg <= 0.0 or order <= 0:
                return w[:, None, :], np.ones(1)
            x, weight = cap_rule(w, math.radians(deg), order)
            return x, weight / weight.sum()

        wi_n, wi_w = nodes(wi, self.divergence_deg, self.divergence_order)
        wo_n, wo_w = nodes(wo, self.aperture_deg, self.aperture_order)
        f = model.eval(np.broadcast_to(wi_n[:, :, None, :], (len(wi), len(wi_w), len(wo_w), 3)),
                       np.broadcast_to(wo_n[:, None, :, :], (len(wo), len(wi_w), len(wo_w), 3)))
        # the detector collects f |cos o| dw; reduction divides by |cos o| at the centre
        cos_ratio = np.abs(wo_n[..., 2]) / np.maximum(np.abs(wo[:, None, 2]), 1e-300)
        return np.einsum("nij,i,nj->n", f, wi_w, wo_w * cos_ratio)


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
