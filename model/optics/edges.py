"""Where a sample's scattering integrand jumps or kinks, as circles on the sphere of directions,
so that the aperture integral and the reduction's smearing can split their caps along them."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class EdgeCircles:
    """Where the integrand jumps or kinks, as circles {w: axis . w = level} in the free
    direction of a pair for given values of the fixed one (the same for wo given wi and for wi
    given wo). Axis z: the horizon (level 0) and, in transmission, facets standing vertical
    (h_z = 0, level -w_fixed.z / e, e = index across / index on the fixed side; GGX's D does
    not vanish there, so f jumps). Axis w_fixed: in transmission a facet seen edge-on (the end
    of the lobe; from the glass, TIR: level -min(e, 1/e)); in reflection inside the denser
    medium, the TIR kink of F (level 2 e^2 - 1). In wo only: the kinks of the multiple-
    scattering tables, linear in theta_o between grid angles (every `table_step_deg`)."""

    n_above: float  # refractive index on the +z side
    n_below: float
    transmits: bool  # False: an opaque conductor (the horizon is its only edge)
    table_step_deg: float | None = None  # the multiple-scattering tables' theta_o step

    def _levels(self, fixed: np.ndarray, free_is_wo: bool) -> tuple[np.ndarray, np.ndarray]:
        """Levels (N, L) of the z family and (N, 2) of the family about the fixed directions
        (a level outside [-1, 1]: no such circle)."""
        n = len(fixed)
        table = (np.cos(np.radians(np.arange(self.table_step_deg, 180.0, self.table_step_deg)))
                 if self.table_step_deg and free_is_wo else np.zeros(0))
        z_levels = np.broadcast_to(np.append(0.0, table), (n, 1 + len(table)))
        if not self.transmits:
            return z_levels, np.full((n, 0), 2.0)
        above = fixed[:, 2] > 0
        e = np.where(above, self.n_below, self.n_above) / np.where(above, self.n_above,
                                                                   self.n_below)
        vertical = -fixed[:, 2] / e
        edge_on = -np.minimum(e, 1.0 / e)
        tir = np.where(e < 1.0, 2.0 * e * e - 1.0, 2.0)
        return (np.concatenate([z_levels, vertical[:, None]], axis=1),
                np.stack([edge_on, tir], axis=1))

    def circles(self, fixed: np.ndarray, free_is_wo: bool = True
                ) -> list[tuple[np.ndarray, np.ndarray]]:
        """[(axis (N, 3), levels (N, L))] per axis for fixed directions (N, 3), on one side."""
        fixed = np.atleast_2d(fixed)
        z_levels, fixed_levels = self._levels(fixed, free_is_wo)
        return [(np.broadcast_to([0.0, 0.0, 1.0], fixed.shape), z_levels),
                (fixed, fixed_levels)]

    def distance(self, fixed: np.ndarray, free: np.ndarray, free_is_wo: bool = True) -> float:
        """Angle (rad) from the free direction (3,) to the nearest circle, for one fixed (3,)."""
        best = np.inf
        angles = (np.arccos(np.clip(free[2], -1.0, 1.0)),
                  np.arccos(np.clip(float(fixed @ free), -1.0, 1.0)))
        for t, levels in zip(angles, self._levels(fixed[None], free_is_wo), strict=True):
            real = levels[0][np.abs(levels[0]) <= 1.0]
            if len(real):
                best = min(best, float(np.min(np.abs(t - np.arccos(real)))))
        return best
