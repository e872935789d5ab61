"""Directions in the plane of incidence, for drawing a BSDF against the signed outgoing angle
as Walter et al. 2007's figures do (the emulator's truth curves, the fitted model's)."""

from __future__ import annotations

import math

import numpy as np


def in_plane_directions(theta_i_deg: float, theta_o_deg: np.ndarray, transmission: bool
                        ) -> tuple[np.ndarray, np.ndarray]:
    """(wi, wo) along the plane of incidence for signed outgoing angles (forward positive)."""
    ti, to = math.radians(theta_i_deg), np.radians(theta_o_deg)
    wi = np.broadcast_to([-math.sin(ti), 0.0, math.cos(ti)], (len(to), 3))
    wo = np.stack([np.sin(to), np.zeros_like(to), -np.cos(to) if transmission else np.cos(to)],
                  axis=1)
    return wi, wo
