"""Reduced BSDF data: what `reduce` produces and `fit`, `plot` and exports consume."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class ReducedData:
    """Calibrated BSDF samples with 1-sigma uncertainties, one entry per measured point.

    Directions are unit vectors in the sample (BSDF) frame of DESIGN.md; `wi` toward the
    source, `wo` toward the detector. `valid` is False for saturated, dark-limited or
    otherwise flagged points, which fits and plots leave out.
    """

    wi: np.ndarray  # (N, 3)
    wo: np.ndarray  # (N, 3)
    bsdf: np.ndarray  # (N,) 1/sr, no cosine factor
    sigma: np.ndarray  # (N,) 1/sr
    valid: np.ndarray  # (N,) bool
    transmission: np.ndarray  # (N,) bool: wo on the interior side
    meta: dict = field(default_factory=dict)  # eta, wavelength_nm, run path, calibration used

    def __post_init__(self) -> None:
        n = len(self.bsdf)
        for name in ("wi", "wo"):
            if getattr(self, name).shape != (n, 3):
                raise ValueError(f"ReducedData.{name} must have shape ({n}, 3)")
        for name in ("sigma", "valid", "transmission"):
            if getattr(self, name).shape != (n,):
                raise ValueError(f"ReducedData.{name} must have shape ({n},)")

    @property
    def theta_i_deg(self) -> np.ndarray:
        """Incidence angle from the normal, degrees."""
        return np.degrees(np.arccos(np.clip(self.wi[:, 2], -1.0, 1.0)))

    @property
    def theta_o_deg(self) -> np.ndarray:
        """Signed in-plane outgoing angle, degrees: the angle of wo from +z (reflection)
        or from -z (transmission), positive on the forward (specular / refracted) side."""
        cos_o = np.where(self.transmission, -self.wo[:, 2], self.wo[:, 2])
        theta = np.degrees(np.arccos(np.clip(cos_o, -1.0, 1.0)))
        # forward is +x at normal incidence (wi_x = 0), else away from the source's side
        forward = np.where(self.wi[:, 0] == 0, 1.0, -np.sign(self.wi[:, 0]))
        return np.where(self.wo[:, 0] * forward < 0, -theta, theta)

    def subset(self, keep: np.ndarray) -> ReducedData:
        """The entries selected by a boolean mask or index array."""
        return ReducedData(
            self.wi[keep], self.wo[keep], self.bsdf[keep], self.sigma[keep],
            self.valid[keep], self.transmission[keep], dict(self.meta),
        )
