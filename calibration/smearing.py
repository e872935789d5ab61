"""What the instrument averages a BSDF over before the detector reports it: the aperture's cap
of outgoing directions and the divergent beam's cone of incoming ones (the fit's forward model
of a reading, beside the point model)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

EDGE_ORDER = 40  # radial order over an aperture that straddles an edge of the lobe (the bench's)
RIM_POINTS = 24  # directions on the aperture's rim probed for an edge of the lobe


def _rim(w: np.ndarray, half_angle_rad: float, n: int) -> np.ndarray:
    """n directions (N, n, 3) on the circle of half-angle half_angle_rad about each w (N, 3)."""
    helper = np.where(np.abs(w[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    t1 = np.cross(w, helper)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(w, t1)
    phi = 2.0 * np.pi * np.arange(n) / n
    ring = np.cos(phi)[None, :, None] * t1[:, None, :] + np.sin(phi)[None, :, None] * t2[:, None, :]
    return math.cos(half_angle_rad) * w[:, None, :] + math.sin(half_angle_rad) * ring


@dataclass(frozen=True)
class Smearing:
    """What the instrument averages the BSDF over: the detector aperture (a cap of half-angle
    aperture_deg about wo, weighted by |cos o| relative to the centre, as the detector collects
    f |cos o| dw and reduction divides by the centre's |cos o|) and the beam's divergence (a
    cone of half-angle divergence_deg about wi), each a cap rule of the given radial order;
    an aperture over which the model falls to zero somewhere (an edge of the lobe) gets
    EDGE_ORDER."""

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

        def smeared(wi: np.ndarray, wo: np.ndarray, order: int) -> tuple[np.ndarray, np.ndarray]:
            wi_n, wi_w = nodes(wi, self.divergence_deg, self.divergence_order)
            wo_n, wo_w = nodes(wo, self.aperture_deg, order)
            f = model.eval(
                np.broadcast_to(wi_n[:, :, None, :], (len(wi), len(wi_w), len(wo_w), 3)),
                np.broadcast_to(wo_n[:, None, :, :], (len(wo), len(wi_w), len(wo_w), 3)))
            # the detector collects f |cos o| dw; reduction divides by |cos o| at the centre
            cos_ratio = np.abs(wo_n[..., 2]) / np.maximum(np.abs(wo[:, None, 2]), 1e-300)
            lit = (f > 0).reshape(len(wi), -1)
            straddles = lit.any(axis=1) & ~lit.all(axis=1)
            return np.einsum("nij,i,nj->n", f, wi_w, wo_w * cos_ratio), straddles

        out, straddles = smeared(wi, wo, self.aperture_order)
        if self.aperture_deg > 0.0 and self.aperture_order > 0:
            # the rule's nodes stop short of the rim: an edge there is found on the rim
            rim = _rim(wo, math.radians(self.aperture_deg), RIM_POINTS)
            lit = np.concatenate([(model.eval(wi[:, None, :], rim) > 0),
                                  (out > 0)[:, None]], axis=1)
            straddles |= lit.any(axis=1) & ~lit.all(axis=1)
        if straddles.any():
            # an edge of the lobe (f falls to 0: GGX's vertical facets, the horizon) inside the
            # aperture: a low-order rule is off by up to its whole jump; the bench takes its
            # top order there too (sim.bench.aperture)
            out[straddles] = smeared(wi[straddles], wo[straddles], EDGE_ORDER)[0]
        return out


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
