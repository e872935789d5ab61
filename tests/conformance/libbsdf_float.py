"""libbsdf's float32 precision at a Zemax table's nodes, from the file's own table: libbsdf keeps
the values as 32-bit floats and blends, along incidence, sample rotation, azimuth and radial, the
two nodes around a query; at a query on a node it still takes the node below with weight 1
(v0 + (v1 - v0) * 1), which returns the node's value off by up to half a float32 ulp of the
larger of the two."""

from __future__ import annotations

import numpy as np

from calibration.exports.zemax import ZemaxTable
from calibration.exports.zemax_measured import MeasuredNodes

HALF_ULP = 2.0 ** -24  # half a float32 ulp of a value, relative, at most


def _nearest(grid: np.ndarray, values: np.ndarray) -> np.ndarray:
    """The index of the grid angle nearest each value (the file holds angles to 1e-9 deg)."""
    return np.abs(grid[:, None] - values[None, :]).argmin(axis=0)


def _around(index: int, size: int) -> np.ndarray:
    """The node and its neighbours along one axis."""
    return np.arange(max(index - 1, 0), min(index + 2, size))


def _azimuths_around(index: int, radial_index: int, azimuth_deg: np.ndarray) -> np.ndarray:
    """The azimuth rows libbsdf may blend at a node: its neighbours, around the circle where the
    row at 360 closes it, and every row at radial 0 (each holds the specular node)."""
    size = len(azimuth_deg)
    if radial_index == 0:
        return np.arange(size)
    if azimuth_deg[-1] != 360.0:
        return _around(index, size)
    rows = size - 1  # the row at 360 repeats row 0
    near = np.mod(np.arange(index - 1, index + 2), rows)
    return np.union1d(near, [rows]) if 0 in near else near


def blend_bounds(table: ZemaxTable, nodes: MeasuredNodes) -> np.ndarray:
    """(len(nodes.point),) the float32 bound of libbsdf's value at each node: HALF_ULP of the
    largest table value among the nodes it blends there (the node's neighbours along each
    axis)."""
    rotation = _nearest(table.sample_rotation_deg, nodes.rotation_deg[nodes.rotation])
    block = _nearest(table.angle_deg, nodes.angle_deg[nodes.block])
    azimuth = _nearest(table.azimuth_deg, nodes.azimuth)
    radial = _nearest(table.radial_deg, nodes.radial)
    largest = np.array([
        np.abs(table.data[np.ix_(_around(r, len(table.sample_rotation_deg)),
                                 _around(a, len(table.angle_deg)),
                                 _azimuths_around(z, d, table.azimuth_deg),
                                 _around(d, len(table.radial_deg)))]).max()
        for r, a, z, d in zip(rotation, block, azimuth, radial, strict=True)])
    return HALF_ULP * largest


def point_bounds(table: ZemaxTable, nodes: MeasuredNodes, n_points: int) -> np.ndarray:
    """(n_points,) blend_bounds per point: the largest over its nodes (a point at normal
    incidence is a node of every sample rotation)."""
    bound = np.zeros(n_points)
    np.maximum.at(bound, nodes.point, blend_bounds(table, nodes))
    return bound
