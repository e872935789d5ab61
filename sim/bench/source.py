"""The light source: wavelength, power with an optional slow drift, beam size and divergence."""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class Dip:
    """The source's power falls by the share `depth` for `duration_s` from `start_s` (seconds of
    the source's clock): a lamp flicker, a laser mode hop."""

    start_s: float
    duration_s: float
    depth: float

    def factor(self, t_s: float) -> float:
        """What the power is multiplied by at time t_s."""
        return 1.0 - self.depth if self.start_s <= t_s < self.start_s + self.duration_s else 1.0


@dataclass(frozen=True)
class Source:
    """A collimated laser-like beam. The power drifts as
    power_w * (1 + drift_fraction * sin(2 pi t / drift_period_s)), t in seconds of the clock
    the bench is given (the emulators': wall seconds since the bench started, like a lamp);
    the beam is a uniform disk of beam_diameter_mm spreading in a cone of divergence_deg
    (half-angle); a `dip` lowers the power for a while."""

    wavelength_nm: float = 632.8
    power_w: float = 1e-3
    beam_diameter_mm: float = 2.0
    divergence_deg: float = 0.0
    drift_fraction: float = 0.0
    drift_period_s: float = 3600.0
    dip: Dip | None = None

    def power_at(self, t_s: float) -> float:
        """Beam power at time t_s, W."""
        dip = 1.0 if self.dip is None else self.dip.factor(t_s)
        if self.drift_fraction == 0.0:
            return self.power_w * dip
        phase = 2.0 * math.pi * t_s / self.drift_period_s
        return self.power_w * (1.0 + self.drift_fraction * math.sin(phase)) * dip

    @property
    def divergence_rad(self) -> float:
        """Divergence half-angle, rad."""
        return math.radians(self.divergence_deg)

    def diameter_at_mm(self, distance_mm: float) -> float:
        """Beam diameter after travelling distance_mm."""
        return self.beam_diameter_mm + 2.0 * distance_mm * math.tan(self.divergence_rad)
