"""Integrals over the unit disk of direction cosines in polar cells about the mirror
direction, where the smooth-surface and ABg peaks are: d^2 beta = cos theta_o d omega, so the
integral of f(wo) over the disk is that of f cos_o over the hemisphere."""

from __future__ import annotations

import numpy as np

#: Radial cell edges in units of the distance to the unit circle: geometric from 1e-7.
EDGES = np.concatenate([[0.0], np.geomspace(1e-7, 1.0, 40)])


def integrate_about_specular(f, wi: np.ndarray, radial: int = 24, azimuths: int = 256,
                             edges: np.ndarray = EDGES) -> float:
    """int f(wo) d^2 beta over the unit disk, by Gauss-Legendre in the radius (cells `edges`
    of the distance from beta0 = -wi_xy to the unit circle) and the trapezoid rule in azimuth."""
    b0 = -wi[:2]
    x, w = np.polynomial.legendre.leggauss(radial)
    phi = np.linspace(0, 2 * np.pi, azimuths + 1)[:-1]
    e = np.stack([np.cos(phi), np.sin(phi)], -1)
    reach = -(e @ b0) + np.sqrt((e @ b0) ** 2 + 1 - b0 @ b0)
    total = 0.0
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        t = lo + (hi - lo) * 0.5 * (x + 1)
        r = reach[:, None] * t[None, :]
        beta = b0 + r[..., None] * e[:, None, :]
        wo = np.concatenate([beta, np.sqrt(np.maximum(1 - np.sum(beta**2, -1), 0))[..., None]],
                            -1)
        total += np.sum(f(wo) * r * reach[:, None] * (hi - lo) * 0.5 * w) * 2 * np.pi / len(phi)
    return float(total)
