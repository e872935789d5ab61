"""Reduced BSDF data: what `reduce` produces and `fit`, `plot` and exports consume."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class ReducedData:
    """Calibrated BSDF samples with 1-sigma uncertainties, one entry per measured point.

    Directions are unit vectors in the sample (BSDF) frame of docs/architecture.md; `wi` toward the
    source, `wo` toward the detector. `valid` is False for saturated, dark-limited or
    otherwise flagged points, which fits and plots leave out. `flags` says why a point is
    suspect (comma-separated, e.g. "signature": the bench's own scatter exceeds the stated
    share of its signal, calibration.signature).

    `shared_rel` (N, k) holds the relative errors the points share: the values carry a common
    relative error shared_rel @ z, z ~ N(0, I_k) (the beam curve's error, common to every point
    it normalises); `sigma` includes each point's own part of it, |bsdf| |shared_rel[i]|. Fits
    take it as a covariance (`whitened`), not as independent noise. None: no shared error.

    `components` is the uncertainty budget (calibration.budget): each named standard
    uncertainty, own or shared; `sigma` is their root sum of squares, u (meta["coverage_k"]: k).
    """

    wi: np.ndarray  # (N, 3)
    wo: np.ndarray  # (N, 3)
    bsdf: np.ndarray  # (N,) 1/sr, no cosine factor
    sigma: np.ndarray  # (N,) 1/sr
    valid: np.ndarray  # (N,) bool
    transmission: np.ndarray  # (N,) bool: wo on the interior side
    meta: dict = field(default_factory=dict)  # eta, wavelength_nm, run path, calibration used
    shared_rel: np.ndarray | None = None  # (N, k) relative errors shared between points
    flags: np.ndarray | None = None  # (N,) str, comma-separated; None: no flags
    # name -> (N,) standard uncertainty in 1/sr: the GUM budget's components (calibration.budget)
    components: dict[str, np.ndarray] = field(default_factory=dict)

    def __post_init__(self) -> None:
        n = len(self.bsdf)
        if self.shared_rel is None:
            self.shared_rel = np.zeros((n, 0))
        if self.flags is None:
            self.flags = np.full(n, "")
        if self.shared_rel.ndim != 2 or len(self.shared_rel) != n:
            raise ValueError(f"ReducedData.shared_rel must have shape ({n}, k)")
        for name in ("wi", "wo"):
            if getattr(self, name).shape != (n, 3):
                raise ValueError(f"ReducedData.{name} must have shape ({n}, 3)")
        for name in ("sigma", "valid", "transmission", "flags"):
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
            self.valid[keep], self.transmission[keep], dict(self.meta), self.shared_rel[keep],
            self.flags[keep], {name: u[keep] for name, u in self.components.items()},
        )

    @property
    def sigma_own(self) -> np.ndarray:
        """Each point's independent 1-sigma: `sigma` without its share of the shared errors."""
        return self._own(self.sigma)

    def _own(self, sigma: np.ndarray) -> np.ndarray:
        """The independent part of a 1-sigma per point: without its share of the shared errors."""
        shared = np.abs(self.bsdf) * np.linalg.norm(self.shared_rel, axis=1)
        return np.sqrt(np.maximum(sigma**2 - shared**2, 0.0))

    def linear_uncertainty(self, gradient: np.ndarray) -> tuple[float, float]:
        """(own, shared) standard uncertainty of sum(gradient * bsdf): from the points'
        independent errors, and from the relative errors they share (shared_rel)."""
        own = float(np.sqrt(np.sum((gradient * self.sigma_own) ** 2)))
        shared = float(np.linalg.norm((gradient * self.bsdf) @ self.shared_rel))
        return own, shared

    def whitened(self, model: np.ndarray, sigma: np.ndarray | None = None) -> np.ndarray:
        """Normalised residuals of model values against the data under the full covariance
        (independent sigma_own plus the shared relative errors, scaled by the model, so a
        normalisation error cannot bias the fit towards low values): the shared errors' z are
        profiled out with their N(0, 1) priors, which is exact for errors linear in z, so the
        sum of squares of the N + k entries returned is the generalised chi-square
        r^T C^-1 r with C = diag(sigma_own^2) + (model shared_rel)(model shared_rel)^T.
        `sigma` replaces the data's own 1-sigma per point (a fit adds its model's Monte Carlo
        error to it); None: `sigma`."""
        own = self.sigma_own if sigma is None else self._own(sigma)
        r = (model - self.bsdf) / own
        if self.shared_rel.shape[1] == 0:
            return r
        a = (model / own)[:, None] * self.shared_rel
        a = np.where(np.isfinite(a), a, 0.0)
        z = -np.linalg.solve(a.T @ a + np.eye(a.shape[1]), a.T @ np.where(np.isfinite(r), r, 0.0))
        return np.concatenate([r + a @ z, z])
