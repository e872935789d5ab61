"""Measured BSDF values spread over one side's hemisphere, about its specular direction: the
quadrature cells of an integral and the interpolation between measured rows (calibration.
integrals). A row is the set of points at one azimuth about the specular direction; between two
neighbouring rows and inside both rows' radial range a cell is covered by the data (linear in the
radial angle along each row, linear in azimuth between the rows), elsewhere it is not."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from calibration.exports.zemax import on_side, scatter_directions, specular_frame

#: Edges of the radial panels, degrees about the specular direction: the standards' cone and
#: window edges (calibration.integrals) fall on panel edges, so their regions are integrated
#: without a partial cell.
PANEL_EDGES_DEG = (0.0, 0.9, 1.8, 2.0, 2.2, 2.5, 3.0, 5.0, 5.85, 10.0, 20.0, 30.0, 45.0, 60.0,
                   75.0, 85.0, 90.0, 105.0, 120.0, 150.0, 180.0)
#: Gauss-Legendre nodes per radial panel.
PANEL_NODES = 6
#: Azimuth cells about the specular direction (3 deg each).
AZIMUTHS = 120
#: Rows' azimuths and radial nodes are matched to this many decimals of a degree.
NODE_DECIMALS = 3


@dataclass(frozen=True)
class Cells:
    """Quadrature cells of one side's hemisphere: directions `wo` (n_az, n_rad, 3) at
    `azimuth_deg` x `radial_deg` about the specular direction, and `weight` (n_az, n_rad), the
    solid angle times |cos theta_o| (0 for cells on the other side), so that the integral of
    f |cos theta_o| over the side is sum(weight * f)."""

    azimuth_deg: np.ndarray
    radial_deg: np.ndarray
    wo: np.ndarray
    weight: np.ndarray

    @property
    def on_side(self) -> np.ndarray:
        """True for the cells in the side's hemisphere."""
        return self.weight > 0


def cells(angle_deg: float, scatter_type: str) -> Cells:
    """The cells about the specular (BRDF) or direct-transmission (BTDF) direction at
    `angle_deg` from the normal: Gauss-Legendre panels in the radial angle, midpoints in
    azimuth."""
    x, w = np.polynomial.legendre.leggauss(PANEL_NODES)
    edges = np.radians(PANEL_EDGES_DEG)
    lo, hi = edges[:-1, None], edges[1:, None]
    radial = (lo + (hi - lo) * 0.5 * (x + 1)).ravel()
    w_radial = ((hi - lo) * 0.5 * w).ravel()
    azimuth_deg = (np.arange(AZIMUTHS) + 0.5) * 360.0 / AZIMUTHS
    radial_deg = np.degrees(radial)
    wo = scatter_directions(angle_deg, scatter_type, azimuth_deg, radial_deg)
    area = np.sin(radial) * w_radial * (2.0 * math.pi / AZIMUTHS)
    weight = np.where(on_side(wo, scatter_type), np.abs(wo[..., 2]) * area[None, :], 0.0)
    return Cells(azimuth_deg, radial_deg, wo, weight)


def specular_coordinates(wo: np.ndarray, angle_deg: float, scatter_type: str
                         ) -> tuple[np.ndarray, np.ndarray]:
    """(azimuth, radial) in degrees of directions `wo` (N, 3) about the specular direction
    (azimuth 0 toward the normal, 90 toward +y: calibration.exports.zemax)."""
    c, e0, e90 = specular_frame(angle_deg, scatter_type)
    radial = np.degrees(np.arccos(np.clip(wo @ c, -1.0, 1.0)))
    azimuth = np.mod(np.degrees(np.arctan2(wo @ e90, wo @ e0)), 360.0)
    return np.round(azimuth, NODE_DECIMALS), np.round(radial, NODE_DECIMALS)


@dataclass(frozen=True)
class RowInterpolation:
    """Cell values from point values, linear in the points: cell (z, r) gets
    `linear[z, r] @ values` where `covered[z, r]`, and `nearest[z, r] @ values` is the nearest
    row's nearest node (the cruder rule whose difference from the linear one measures the
    interpolation's error)."""

    linear: np.ndarray  # (n_az, n_rad, n_points)
    nearest: np.ndarray  # (n_az, n_rad, n_points)
    covered: np.ndarray  # (n_az, n_rad) bool


def _rows(azimuth: np.ndarray, radial: np.ndarray, mirror: bool
          ) -> dict[float, tuple[np.ndarray, np.ndarray]]:
    """Per row azimuth: (radial nodes, (n_nodes, n_points) coefficients averaging the points at
    each node). Points at the specular direction itself belong to every row; `mirror` adds each
    point to the row mirrored across the plane of incidence (an isotropic sample)."""
    n = len(azimuth)
    centre = np.flatnonzero(radial < 10.0 ** -NODE_DECIMALS)
    members: dict[float, list[int]] = {}
    for j in np.flatnonzero(radial >= 10.0 ** -NODE_DECIMALS):
        keys = {float(azimuth[j])}
        if mirror:
            keys.add(float(np.round(np.mod(360.0 - azimuth[j], 360.0), NODE_DECIMALS)))
        for key in keys:
            members.setdefault(key, []).append(int(j))
    rows = {}
    for key, listed in members.items():
        at = np.concatenate([centre, listed]).astype(int)
        nodes, which = np.unique(radial[at], return_inverse=True)
        coefficient = np.zeros((len(nodes), n))
        np.add.at(coefficient, (which, at), 1.0)
        rows[key] = (nodes, coefficient / coefficient.sum(axis=1, keepdims=True))
    return rows


def _along(nodes: np.ndarray, coefficient: np.ndarray, radial: np.ndarray
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(linear, nearest, inside) of one row at the cells' radial angles: (n_rad, n_points)
    coefficients and whether each radial angle lies within the row's nodes."""
    inside = (radial >= nodes[0]) & (radial <= nodes[-1])
    hi = np.clip(np.searchsorted(nodes, radial), 1, max(len(nodes) - 1, 1))
    lo = hi - 1
    if len(nodes) == 1:
        lo = hi = np.zeros(len(radial), int)
    span = nodes[hi] - nodes[lo]
    s = np.where(span > 0, (radial - nodes[lo]) / np.where(span > 0, span, 1.0), 0.0)
    s = np.clip(s, 0.0, 1.0)[:, None]
    linear = (1 - s) * coefficient[lo] + s * coefficient[hi]
    nearest = np.where(s < 0.5, coefficient[lo], coefficient[hi])
    return linear, nearest, inside


def row_interpolation(grid: Cells, azimuth: np.ndarray, radial: np.ndarray, mirror: bool
                      ) -> RowInterpolation:
    """The interpolation of point values at (azimuth, radial) (degrees, specular_coordinates)
    onto the cells: linear along each row and between neighbouring rows (circularly) where the
    cell lies inside both rows' radial range; no cell is covered with fewer than two rows."""
    n_az, n_rad, n = len(grid.azimuth_deg), len(grid.radial_deg), len(azimuth)
    linear = np.zeros((n_az, n_rad, n))
    nearest = np.zeros((n_az, n_rad, n))
    covered = np.zeros((n_az, n_rad), bool)
    rows = _rows(azimuth, radial, mirror)
    if len(rows) < 2:
        return RowInterpolation(linear, nearest, covered)
    keys = sorted(rows)
    along = {key: _along(*rows[key], grid.radial_deg) for key in keys}
    bounds = np.array([*keys, keys[0] + 360.0])
    for z, chi in enumerate(grid.azimuth_deg):
        chi = chi if chi >= keys[0] else chi + 360.0
        k = int(np.searchsorted(bounds, chi, side="right")) - 1
        a, b = keys[k % len(keys)], keys[(k + 1) % len(keys)]
        t = (chi - bounds[k]) / (bounds[k + 1] - bounds[k])
        (lin_a, near_a, in_a), (lin_b, near_b, in_b) = along[a], along[b]
        linear[z] = (1 - t) * lin_a + t * lin_b
        nearest[z] = near_a if t < 0.5 else near_b
        covered[z] = in_a & in_b
    return RowInterpolation(linear, nearest, covered)
