"""Instrument scatter: light the bench itself puts into the aperture, sample in the beam or not.

A halo about the beam axis (light scattered by the source optics), radiant intensity per unit
beam power h(gamma) = A (1 + (gamma / w)^2)^(-s / 2) with gamma the angle from the
straight-through direction (arm 180), w `halo_width_deg` and s `halo_slope` (the Harvey-Shack
form of optics scatter: flat inside w, falling as gamma^-s beyond); A makes the halo hold
`halo_fraction` of the beam's power over the whole sphere. And stray light from the arm:
`arm_fraction` (1 + `arm_variation` cos(arm)) of the beam's power reaches the detector wherever
it is. Both are deterministic, add to what the sample sends, and are all a signature reading
(the sample retracted) sees besides the direct beam.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property, lru_cache

import numpy as np

from sim.bench.geometry import angle_from_beam_rad

#: Gauss-Legendre nodes per panel of the normalisation; panels double in width from w / 16.
NORM_NODES = 32
#: Gauss-Legendre nodes per piece of the aperture integral (tests/bench: 1e-9 of the reference).
CAP_NODES = 16


@dataclass(frozen=True)
class InstrumentScatter:
    """The [sim.stray] table: halo about the beam and stray light from the arm (0: none)."""

    halo_fraction: float = 0.0
    halo_width_deg: float = 1.0
    halo_slope: float = 3.0
    arm_fraction: float = 0.0
    arm_variation: float = 0.0

    @cached_property
    def amplitude_per_sr(self) -> float:
        """A: the halo's intensity on the beam axis per unit beam power (1/sr), from
        2 pi int_0^pi shape(gamma) sin(gamma) dgamma by Gauss-Legendre on doubling panels."""
        if self.halo_fraction == 0.0:
            return 0.0
        w = math.radians(self.halo_width_deg)
        edges = np.unique(np.clip(np.concatenate([[0.0], w * 2.0 ** np.arange(-4.0, 12.0),
                                                  [math.pi]]), 0.0, math.pi))
        x, weight = _gauss(NORM_NODES)
        half = 0.5 * np.diff(edges)[:, None]
        gamma = (0.5 * (edges[1:] + edges[:-1]))[:, None] + half * x
        integral = 2.0 * math.pi * float(np.sum(half * weight * self.shape(gamma)
                                                * np.sin(gamma)))
        return self.halo_fraction / integral

    def shape(self, gamma_rad: np.ndarray) -> np.ndarray:
        """The halo's profile, 1 on the beam axis."""
        ratio = np.asarray(gamma_rad, dtype=np.float64) / math.radians(self.halo_width_deg)
        return (1.0 + ratio**2) ** (-0.5 * self.halo_slope)

    def halo_per_sr(self, gamma_rad: np.ndarray) -> np.ndarray:
        """Halo intensity per unit beam power at gamma from the beam axis, 1/sr."""
        return self.amplitude_per_sr * self.shape(gamma_rad)

    def cap_integral(self, t_rad: float, aperture_rad: float) -> float:
        """Halo power per unit beam power in a cap of half-angle aperture_rad whose centre is
        t_rad from the beam axis: int h(gamma) 2 psi(gamma) sin(gamma) dgamma, psi half the arc
        of the circle gamma about the axis inside the cap, by Gauss-Legendre in pieces cut where
        the circles start to leave the cap and at the halo's scales, each mapped
        gamma = m + h sin(s) (which absorbs the square-root ends of psi)."""
        lo, hi = max(0.0, t_rad - aperture_rad), min(math.pi, t_rad + aperture_rad)
        w = math.radians(self.halo_width_deg)
        cuts = np.concatenate([[lo, hi, aperture_rad - t_rad], w * 2.0 ** np.arange(-4.0, 12.0)])
        edges = np.unique(cuts[(cuts >= lo) & (cuts <= hi)])
        x, weight = _gauss(CAP_NODES)
        mid, half = 0.5 * (edges[1:] + edges[:-1]), 0.5 * np.diff(edges)
        s = 0.5 * math.pi * x
        gamma = mid[:, None] + half[:, None] * np.sin(s)
        d_gamma = half[:, None] * 0.5 * math.pi * np.cos(s) * weight
        cos_psi = ((math.cos(aperture_rad) - np.cos(gamma) * math.cos(t_rad))
                   / np.maximum(np.sin(gamma) * math.sin(t_rad), 1e-300))
        psi = np.arccos(np.clip(cos_psi, -1.0, 1.0))
        return float(np.sum(self.halo_per_sr(gamma) * 2.0 * psi * np.sin(gamma) * d_gamma))

    def fraction(self, arm_deg: float, elevation_deg: float, aperture_rad: float) -> float:
        """Share of the beam's power the bench adds to a reading at (arm, elevation) through an
        aperture of half-angle aperture_rad: the halo over the aperture plus the arm's stray."""
        total = self.arm_fraction * (1.0 + self.arm_variation * math.cos(math.radians(arm_deg)))
        if self.halo_fraction:
            total += self.cap_integral(float(angle_from_beam_rad(arm_deg, elevation_deg)),
                                       aperture_rad)
        return total


@lru_cache(maxsize=4)
def _gauss(n: int) -> tuple[np.ndarray, np.ndarray]:
    return np.polynomial.legendre.leggauss(n)
