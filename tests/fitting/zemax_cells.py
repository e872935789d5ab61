"""The check that a measured Zemax table holds the reduced data where measured, by an
independent route: each point's cell is found as the grid direction (scatter_directions)
nearest to its own wo, mirrored across the plane of incidence for plane-symmetric tables; and a
table's TIS recomputed from its cells (table_tis)."""

from __future__ import annotations

import numpy as np

from calibration.exports.zemax import ZemaxTable, scatter_directions, tis_weights
from calibration.reduced import ReducedData


def assert_measured_cells(table: ZemaxTable, points: ReducedData) -> None:
    """Every point's value (its mean with points at the same direction; negative ones written
    as 0) is the table's value at the point's direction, to the file's 7 digits."""
    assert len(points.bsdf) > 0
    angles = (np.radians(points.theta_i_deg) if table.scatter_type == "BRDF" else
              np.arcsin(np.sin(np.radians(points.theta_i_deg)) / points.meta["eta"]))
    for a, angle in enumerate(table.angle_deg):
        at = np.flatnonzero(np.abs(np.degrees(angles) - angle) < 1e-3)
        grid = scatter_directions(angle, table.scatter_type, table.azimuth_deg,
                                  table.radial_deg).reshape(-1, 3)
        for j in at:
            wo = points.wo[j]
            if table.symmetry == "PlaneSymmetrical":
                wo = wo * np.array([1.0, np.sign(wo[1]) or 1.0, 1.0])
            distance = np.linalg.norm(grid - wo, axis=1)
            cell = int(np.argmin(distance))
            assert distance[cell] < 1e-6, (angle, wo)
            same = at[np.linalg.norm(points.wo[at] - points.wo[j], axis=1) < 1e-9]
            expected = max(float(np.mean(points.bsdf[same])), 0.0)
            value = table.data[0, a].reshape(-1)[cell]
            assert abs(value - expected) <= 1e-6 * expected, (angle, wo, value, expected)


def table_tis(table: ZemaxTable, rotation: int, angle: int) -> float:
    """TIS recomputed from the tabulated values alone (tis_weights): a reader's consistency
    check of the TIS line."""
    return float(np.sum(tis_weights(table, angle) * table.data[rotation, angle]))
