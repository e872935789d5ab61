"""A Zemax tabular BSDF table from measured data (`Source Measured`): each measured point at
its own grid node (the grid is the model grid plus every measured azimuth and radial angle),
linear interpolation between measured nodes along each measured azimuth row, and the fitted
model only where there is no data. Isotropic samples are written `PlaneSymmetrical` (points
off the plane of incidence folded onto azimuths 0..180). A run with sample azimuths has one
`SampleRotation` per azimuth (measured_nodes). Each block's comment says which of its cells are
measured, interpolated and modelled, and gives its TIS, the modelled cells' share of it and its
standard uncertainty by term: the measured values (own and shared errors, ReducedData), the
interpolation (what linear interpolation makes of the model), the model fill (its share times
the model's RMS relative disagreement with the block's data) and the grid's quadrature (its
sum of the model against a fine rule)."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from calibration.exports.measured import spherical_deg
from calibration.exports.zemax import (
    ZemaxTable,
    hemisphere_integral,
    on_side,
    radial_grid,
    scatter_directions,
    specular_frame,
    standard_azimuth,
    tis_weights,
    turned,
)
from calibration.reduced import ReducedData
from calibration.values import CalibrationError

#: Grid nodes of measured angles, degrees: 1e-6 deg, so that a reader interpolating at a
#: point's own direction stays within 1e-5 relative of its node even on a steep lobe edge.
NODE_DECIMALS = 6


@dataclass
class MeasuredNodes:
    """Where one side's points sit in a table: its SampleRotation and incidence blocks, and
    for each placement of a point (a normal-incidence point sits in every rotation's block)
    the point's index, its rotation and incidence block and its (azimuth, radial) node."""

    rotation_deg: np.ndarray  # (R,): the sample's azimuth, 180 - phi_i of its incidences
    incidence_deg: np.ndarray  # (A,)
    angle_deg: np.ndarray  # (A,): AngleOfIncidence
    point: np.ndarray  # (M,) index into the side's points
    rotation: np.ndarray  # (M,)
    block: np.ndarray  # (M,)
    azimuth: np.ndarray  # (M,) degrees
    radial: np.ndarray  # (M,) degrees


def measured_nodes(good: ReducedData, scatter_type: str, eta: float, isotropic: bool
                   ) -> MeasuredNodes:
    """The blocks and grid nodes (degrees) a table needs to hold each of one side's points at
    its own direction. A point lit from azimuth phi_i belongs to SampleRotation 180 - phi_i
    (the sample turned by that much about its normal, gonio's azimuth stage, its source then
    on -x of the turned frame); one at normal incidence to every rotation."""
    if len(good.bsdf) == 0:
        raise CalibrationError(f"zemax: no valid {scatter_type} point to tabulate")
    theta_i, phi_i = spherical_deg(good.wi)
    tilted = np.sin(np.radians(theta_i)) > 1e-12
    own = np.round(np.mod(180.0 - phi_i, 360.0), 3)
    rotations = np.unique(own[tilted]) if tilted.any() else np.zeros(1)
    incidence, block_of = np.unique(np.round(theta_i, 3), return_inverse=True)
    angle_deg = (incidence if scatter_type == "BRDF" else
                 np.degrees(np.arcsin(np.sin(np.radians(incidence)) / eta)))
    point, rotation = [], []
    for r, p in enumerate(rotations):
        at = np.flatnonzero(~tilted | (own == p))
        point.append(at)
        rotation.append(np.full(len(at), r))
    point_all, rotation_all = np.concatenate(point), np.concatenate(rotation)
    block = block_of[point_all]
    azimuth, radial = np.zeros(len(point_all)), np.zeros(len(point_all))
    for r, p in enumerate(rotations):
        for a, angle in enumerate(angle_deg):
            sel = (rotation_all == r) & (block == a)
            c, e0, e90 = specular_frame(angle, scatter_type)
            wo = turned(good.wo[point_all[sel]], p)
            radial[sel] = np.degrees(np.arctan2(np.linalg.norm(np.cross(wo, c), axis=1),
                                                wo @ c))
            azimuth[sel] = np.degrees(np.arctan2(wo @ e90, wo @ e0))
    # rounded, then taken into [0, 360): 359.9999999 is the node 0 (the row 360 repeats it)
    azimuth = np.mod(np.round(azimuth, NODE_DECIMALS), 360.0)
    azimuth = np.where(radial < 10.0 ** -NODE_DECIMALS, 0.0, azimuth)
    if isotropic:
        azimuth = np.where(azimuth > 180.0, 360.0 - azimuth, azimuth)
    return MeasuredNodes(rotations, incidence, angle_deg, point_all, rotation_all, block,
                         azimuth, np.round(radial, NODE_DECIMALS))


def measured_table(data: ReducedData, scatter_type: str, eta: float,
                   model_eval: Callable[[np.ndarray, np.ndarray], np.ndarray],
                   width_deg: float, isotropic: bool, comments: list[str],
                   model_name: str = "the fitted model") -> ZemaxTable:
    """The table of one side (BRDF | BTDF) of `data`'s valid points, filled by model_eval(wi,
    wo) (1/sr, sample frame) where there is no data (the points' blocks: measured_nodes)."""
    good = data.subset(data.valid & (data.transmission == (scatter_type == "BTDF")))
    nodes = measured_nodes(good, scatter_type, eta, isotropic)
    azimuth = np.unique(np.concatenate([standard_azimuth(isotropic), nodes.azimuth]))
    radial = np.unique(np.concatenate([radial_grid(width_deg), nodes.radial]))
    symmetry = "PlaneSymmetrical" if isotropic else "Asymmetrical"
    shape = (len(nodes.rotation_deg), len(nodes.incidence_deg))
    values = np.zeros((*shape, len(azimuth), len(radial)))
    tis = np.zeros(shape)
    table = ZemaxTable(scatter_type, symmetry, nodes.rotation_deg, nodes.angle_deg, azimuth,
                       radial, values, tis, list(comments), "Measured")
    for r, a in np.ndindex(shape):
        at = (nodes.rotation == r) & (nodes.block == a)
        note = _fill_block(table, r, a, nodes.incidence_deg[a], good.subset(nodes.point[at]),
                           (nodes.azimuth[at], nodes.radial[at]), model_eval, width_deg,
                           model_name)
        rotation = (f"SampleRotation {nodes.rotation_deg[r]:g} " if len(nodes.rotation_deg) > 1
                    else "")
        table.comments.append(f"block {rotation}AngleOfIncidence {nodes.angle_deg[a]:g} "
                              f"(theta_i {nodes.incidence_deg[a]:g} deg): {note}")
    return table


def _fill_block(table: ZemaxTable, r: int, a: int, theta_i_deg: float, points: ReducedData,
                at: tuple[np.ndarray, np.ndarray],
                model_eval: Callable[[np.ndarray, np.ndarray], np.ndarray], width_deg: float,
                model_name: str) -> str:
    """Fill the block (rotation r, angle a) of `table` from its points at their (azimuth,
    radial) nodes `at` and the model elsewhere, with its TIS; the block's note."""
    scatter_type, angle = table.scatter_type, float(table.angle_deg[a])
    rotation = float(table.sample_rotation_deg[r])
    t = math.radians(theta_i_deg)
    wi = turned(np.array([-math.sin(t), 0.0, math.cos(t)]), -rotation)  # sample frame
    grid = scatter_directions(angle, scatter_type, table.azimuth_deg, table.radial_deg)
    wo = turned(grid, -rotation)
    inside = on_side(grid, scatter_type)

    def model(w: np.ndarray) -> np.ndarray:
        return model_eval(np.broadcast_to(wi, w.shape), w)

    coefficient, measured, interpolated = _cell_weights(*at, table.azimuth_deg,
                                                        table.radial_deg)
    from_data = measured | interpolated
    data_cells = coefficient @ points.bsdf
    negative = int(np.sum(measured & (data_cells < 0)))
    model_cells = np.where(inside, model(wo), 0.0)
    if table.azimuth_deg[-1] == 360.0:  # the closing row: azimuth 0's cells, bit for bit
        model_cells[-1] = model_cells[0]
    cells = np.where(from_data, np.maximum(data_cells, 0.0), model_cells)
    table.data[r, a] = cells
    weights = tis_weights(table, a)
    table.tis[r, a] = float(np.sum(weights * cells))
    # the grid's quadrature error, as seen on the model: its sum against a fine rule
    u_grid = abs(float(np.sum(weights * model_cells))
                 - hemisphere_integral(lambda w: model(turned(w, -rotation)), scatter_type,
                                       angle, width_deg))
    u_data = math.hypot(*points.linear_uncertainty(np.tensordot(weights, coefficient, 2)))
    at_points = model(points.wo)
    u_interp = abs(float(np.sum(weights * interpolated
                                * (coefficient @ at_points - model_cells))))
    model_share = float(np.sum(weights * np.where(from_data, 0.0, model_cells)))
    u_fill = _fill_uncertainty(points, at_points, model_share)
    return (f"measured at {int(measured.sum())} of its {int(inside.sum())} cells, interpolated "
            f"between them at {int((interpolated & inside).sum())}, {model_name} at the other "
            f"{int((inside & ~from_data).sum())}"
            + (f"; {negative} negative measured values written as 0" if negative else "")
            + f"; TIS {table.tis[r, a]:.6g}, of it {model_share:.3g} from the model; standard "
            f"uncertainty +- {u_data:.2g} from the measured values, +- {u_interp:.2g} from "
            f"interpolation, +- {u_fill:.2g} from the model fill, +- {u_grid:.2g} from the "
            f"grid's quadrature, combined +- "
            f"{math.sqrt(u_data**2 + u_interp**2 + u_fill**2 + u_grid**2):.2g}")


def _cell_weights(azimuth_at: np.ndarray, radial_at: np.ndarray, azimuth: np.ndarray,
                  radial: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(coefficient[z, r, j], measured, interpolated): the weight of point j in cell (z, r),
    and which cells hold a measured node or lie between two along their azimuth row. A point
    at the specular direction (radial 0) is every azimuth row's node at radial 0, as all
    those cells are that one direction."""
    z_of = np.searchsorted(azimuth, azimuth_at)
    r_of = np.searchsorted(radial, radial_at)
    specular = np.flatnonzero(r_of == 0)
    coefficient = np.zeros((len(azimuth), len(radial), len(azimuth_at)))
    measured = np.zeros((len(azimuth), len(radial)), bool)
    interpolated = np.zeros_like(measured)
    for z in range(len(azimuth)) if len(specular) else np.unique(z_of):
        row = np.union1d(np.flatnonzero((z_of == z) & (r_of > 0)), specular)
        nodes = np.unique(r_of[row])
        for r in nodes:  # repeated points at one node: their mean
            at = row[r_of[row] == r]
            coefficient[z, r, at] = 1.0 / len(at)
        measured[z, nodes] = True
        for lo, hi in zip(nodes[:-1], nodes[1:], strict=True):
            for r in range(lo + 1, hi):
                s = (radial[r] - radial[lo]) / (radial[hi] - radial[lo])
                coefficient[z, r] = (1 - s) * coefficient[z, lo] + s * coefficient[z, hi]
                interpolated[z, r] = True
    if azimuth[-1] == 360.0:  # the closing row repeats azimuth 0
        for cells in (coefficient, measured, interpolated):
            cells[-1] = cells[0]
    return coefficient, measured, interpolated


def _fill_uncertainty(points: ReducedData, expected: np.ndarray, model_share: float) -> float:
    """Standard uncertainty of the modelled cells' share of a TIS: that share times the RMS
    relative difference between the model (`expected` at the block's points) and their
    measured values (how far the model is seen to stray from the data where both are known;
    a block without data: all of it)."""
    keep = expected > 0
    if not keep.any():
        return abs(model_share)
    return abs(model_share) * float(np.sqrt(np.mean((points.bsdf[keep] / expected[keep] - 1.0)
                                                    ** 2)))

