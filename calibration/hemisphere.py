"""Measured BSDF values spread over one side's hemisphere: the quadrature cells of an integral,
about the specular direction (calibration.integrals), and the interpolation between measured
rows. A row is the set of points at one azimuth about the side's normal (an in-plane scan has
two: forward and backward); between two neighbouring rows and inside both rows' range of angles
from the normal a cell is covered by the data (linear in that angle along each row, linear in
azimuth between the rows); beyond the rows' range each row's end value holds (or, to estimate
that hold's error, the parabola through the row's end nodes continues)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calibration.exports.zemax import on_side, scatter_directions

#: Edges of the radial panels, degrees about the specular direction: the standards' cone and
#: window edges (calibration.integrals) fall on panel edges, so their regions are integrated
#: without a partial cell; the panels narrow towards the specular direction, where a glossy
#: lobe (Beckmann alpha 0.001 spans about 0.1 deg) must be resolved.
PANEL_EDGES_DEG = (0.0, 0.05, 0.1, 0.2, 0.45, 0.9, 1.8, 2.0, 2.2, 2.5, 3.0, 5.0, 5.85, 10.0,
                   20.0, 30.0, 45.0, 60.0, 75.0, 85.0, 90.0, 105.0, 120.0, 150.0, 180.0)
#: Gauss-Legendre nodes per radial panel.
PANEL_NODES = 6
#: Edges of the azimuth panels, degrees from the plane of incidence (0 and 180 deg about the
#: specular direction), in each of the four quadrants: they narrow towards the plane, where a
#: glossy lobe at grazing incidence, flattened across it by cos theta_i, lies within a few
#: degrees of azimuth (Beckmann alpha 0.002 at 85 deg: about 5 deg).
AZIMUTH_PANEL_EDGES_DEG = (0.0, 0.5, 1.0, 2.0, 4.0, 8.0, 15.0, 30.0, 60.0, 90.0)
#: Gauss-Legendre nodes per azimuth panel.
AZIMUTH_PANEL_NODES = 4
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


def _panels(edges_deg: np.ndarray, nodes: int) -> tuple[np.ndarray, np.ndarray]:
    """(nodes, weights), radians, of Gauss-Legendre rules of `nodes` points on each panel
    between consecutive edges (degrees)."""
    x, w = np.polynomial.legendre.leggauss(nodes)
    edges = np.radians(edges_deg)
    lo, hi = edges[:-1, None], edges[1:, None]
    return (lo + (hi - lo) * 0.5 * (x + 1)).ravel(), ((hi - lo) * 0.5 * w).ravel()


def cells(angle_deg: float, scatter_type: str) -> Cells:
    """The cells about the specular (BRDF) or direct-transmission (BTDF) direction at
    `angle_deg` from the normal: Gauss-Legendre panels in the radial angle and in azimuth."""
    radial, w_radial = _panels(np.array(PANEL_EDGES_DEG), PANEL_NODES)
    quadrant = np.array(AZIMUTH_PANEL_EDGES_DEG)
    azimuth, w_azimuth = _panels(np.concatenate([quadrant, 180.0 - quadrant[-2::-1],
                                                 180.0 + quadrant[1:], 360.0 - quadrant[-2::-1]]),
                                 AZIMUTH_PANEL_NODES)
    azimuth_deg, radial_deg = np.degrees(azimuth), np.degrees(radial)
    wo = scatter_directions(angle_deg, scatter_type, azimuth_deg, radial_deg)
    area = w_azimuth[:, None] * (np.sin(radial) * w_radial)[None, :]
    weight = np.where(on_side(wo, scatter_type), np.abs(wo[..., 2]) * area, 0.0)
    return Cells(azimuth_deg, radial_deg, wo, weight)


def side_coordinates(wo: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(azimuth, radial) in degrees of directions `wo` (..., 3) about the normal of their side:
    the angle from +z or -z, and the azimuth from +x (the forward side of an incidence from -x)
    toward +y, in [0, 360)."""
    radial = np.degrees(np.arccos(np.clip(np.abs(wo[..., 2]), 0.0, 1.0)))
    azimuth = np.degrees(np.arctan2(wo[..., 1], wo[..., 0]))
    return np.mod(np.round(azimuth, NODE_DECIMALS), 360.0), np.round(radial, NODE_DECIMALS)


@dataclass(frozen=True)
class RowInterpolation:
    """Cell values from point values, linear in the points: a cell gets
    `linear[cell] @ values` (inside the rows' radial range where `covered`, held or continued
    beyond it), and `nearest[cell] @ values` takes the nearest row's value alone (the cruder
    rule in azimuth, whose difference from the linear one measures the azimuthal
    interpolation's error); a cell no row reaches has zero coefficients."""

    linear: np.ndarray  # (..., n_points)
    nearest: np.ndarray  # (..., n_points)
    covered: np.ndarray  # (...) bool


def _rows(azimuth: np.ndarray, radial: np.ndarray, mirror: bool, thin: tuple[int, int] | None
          ) -> dict[float, tuple[np.ndarray, np.ndarray]]:
    """Per row azimuth: (radial nodes, (n_nodes, n_points) coefficients averaging the points at
    each node). Points at the normal itself belong to every row, and the opposite row's points
    continue it through the normal at negative angles (so a cell between the normal and a row's
    first point is covered); `mirror` adds each point to the row mirrored across the plane of
    incidence (an isotropic sample); `thin` 0 or 1 drops the inner nodes of that parity (the
    row's ends stay)."""
    n = len(azimuth)
    centre = np.flatnonzero(radial < 10.0 ** -NODE_DECIMALS)
    members: dict[float, list[int]] = {}
    for j in np.flatnonzero(radial >= 10.0 ** -NODE_DECIMALS):
        keys = {float(azimuth[j])}
        if mirror:
            keys.add(float(np.mod(np.round(360.0 - azimuth[j], NODE_DECIMALS), 360.0)))
        for key in keys:
            members.setdefault(key, []).append(int(j))
    rows = {}
    for key, listed in members.items():
        across = members.get(float(np.mod(key + 180.0, 360.0)), [])
        at = np.concatenate([centre, listed, across]).astype(int)
        signed = np.concatenate([radial[centre], radial[listed], -radial[across]])
        nodes, which = np.unique(signed, return_inverse=True)
        coefficient = np.zeros((len(nodes), n))
        np.add.at(coefficient, (which, at), 1.0)
        keep = np.ones(len(nodes), bool)
        if thin is not None:
            stride, phase = thin
            keep[1:-1] = np.arange(1, len(nodes) - 1) % stride == phase
        rows[key] = (nodes[keep], (coefficient / coefficient.sum(axis=1, keepdims=True))[keep])
    return rows


def _end_parabola(nodes: np.ndarray, coefficient: np.ndarray, radial: np.ndarray
                  ) -> np.ndarray:
    """(N, n_points) coefficients at radial angles (N,) of the parabola through a row's three
    nodes nearest each end (the first three below the row, the last three above it)."""
    at = np.where(radial < nodes[0], 0, len(nodes) - 3)
    x = np.stack([nodes[at + k] for k in range(3)], axis=1)
    out = np.zeros((len(radial), coefficient.shape[1]))
    for k in range(3):
        a, b = (x[:, j] for j in range(3) if j != k)
        weight = (radial - a) * (radial - b) / ((x[:, k] - a) * (x[:, k] - b))
        out += weight[:, None] * coefficient[at + k]
    return out


def _along(nodes: np.ndarray, coefficient: np.ndarray, radial: np.ndarray, extrapolate: bool
           ) -> tuple[np.ndarray, np.ndarray]:
    """(linear, inside) of one row at radial angles (N,): (N, n_points) coefficients and
    whether each radial angle lies within the row's nodes; beyond the row's ends the end
    node's value holds, or with `extrapolate` the parabola through its three end nodes (the
    end interval's line in a row of two) continues."""
    inside = (radial >= nodes[0]) & (radial <= nodes[-1])
    hi = np.clip(np.searchsorted(nodes, radial), 1, max(len(nodes) - 1, 1))
    lo = hi - 1
    if len(nodes) == 1:
        lo = hi = np.zeros(len(radial), int)
    span = nodes[hi] - nodes[lo]
    s = np.where(span > 0, (radial - nodes[lo]) / np.where(span > 0, span, 1.0), 0.0)
    s = (s if extrapolate else np.clip(s, 0.0, 1.0))[:, None]
    linear = (1 - s) * coefficient[lo] + s * coefficient[hi]
    if extrapolate and len(nodes) >= 3:
        linear = np.where(inside[:, None], linear, _end_parabola(nodes, coefficient, radial))
    return linear, inside


def row_interpolation(cell_azimuth: np.ndarray, cell_radial: np.ndarray, azimuth: np.ndarray,
                      radial: np.ndarray, mirror: bool, thin: tuple[int, int] | None = None,
                      extrapolate: bool = False) -> RowInterpolation:
    """The interpolation of point values at (azimuth, radial) (degrees, side_coordinates) onto
    cells at (cell_azimuth, cell_radial): linear along each row and, circularly, between the
    two rows either side of a cell; covered where the cell lies inside both rows' radial
    range, beyond it each row's end value held (or the parabola through its end nodes
    continued: `extrapolate`); with fewer than two rows nothing is covered or reached.
    `thin` (stride, phase): every stride-th inner node of each row only (_rows)."""
    shape, n = cell_azimuth.shape, len(azimuth)
    chi, theta = cell_azimuth.ravel(), cell_radial.ravel()
    rows = _rows(azimuth, radial, mirror, thin)
    if len(rows) < 2:
        return RowInterpolation(np.zeros((*shape, n)), np.zeros((*shape, n)),
                                np.zeros(shape, bool))
    keys = sorted(rows)
    linear_rows, inside_rows = (np.stack(a) for a in zip(
        *(_along(*rows[key], theta, extrapolate) for key in keys), strict=True))
    bounds = np.array([*keys, keys[0] + 360.0])
    chi = np.where(chi >= keys[0], chi, chi + 360.0)
    k = np.clip(np.searchsorted(bounds, chi, side="right") - 1, 0, len(keys) - 1)
    a, b = k, (k + 1) % len(keys)
    t = ((chi - bounds[k]) / (bounds[k + 1] - bounds[k]))[:, None]
    cell = np.arange(len(chi))
    linear = (1 - t) * linear_rows[a, cell] + t * linear_rows[b, cell]
    nearest = np.where(t < 0.5, linear_rows[a, cell], linear_rows[b, cell])
    covered = inside_rows[a, cell] & inside_rows[b, cell]
    return RowInterpolation(linear.reshape(*shape, n), nearest.reshape(*shape, n),
                            covered.reshape(shape))
