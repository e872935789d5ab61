"""A Zemax tabular BSDF table from measured data (`Source Measured`): each measured point at
its own grid node (the grid is the model grid plus every measured azimuth and radial angle),
linear interpolation between measured nodes along each measured azimuth row, and the fitted
model only where there is no data. Isotropic samples are written `PlaneSymmetrical` (points
off the plane of incidence folded onto azimuths 0..180). Each block's comment says which of
its cells are measured, interpolated and modelled, and gives its TIS with the standard
uncertainty propagated from the measured values (own and shared errors, ReducedData)."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from calibration.exports.zemax import (
    ZemaxTable,
    hemisphere_integral,
    on_side,
    radial_grid,
    scatter_directions,
    specular_frame,
    standard_azimuth,
    tis_weights,
)
from calibration.reduced import ReducedData
from calibration.values import CalibrationError

#: Grid nodes of measured angles, degrees: 1e-6 deg, so that a reader interpolating at a
#: point's own direction stays within 1e-5 relative of its node even on a steep lobe edge.
NODE_DECIMALS = 6


def _nodes(data: ReducedData, scatter_type: str, angle_deg: np.ndarray, block: np.ndarray,
           fold: bool) -> tuple[np.ndarray, np.ndarray]:
    """(azimuth, radial) in degrees of each point about its block's specular direction."""
    azimuth, radial = np.zeros(len(block)), np.zeros(len(block))
    for a, angle in enumerate(angle_deg):
        sel = block == a
        c, e0, e90 = specular_frame(angle, scatter_type)
        wo = data.wo[sel]
        radial[sel] = np.degrees(np.arctan2(np.linalg.norm(np.cross(wo, c), axis=1), wo @ c))
        azimuth[sel] = np.mod(np.degrees(np.arctan2(wo @ e90, wo @ e0)), 360.0)
    azimuth = np.where(radial < 10.0 ** -NODE_DECIMALS, 0.0, azimuth)
    if fold:
        azimuth = np.where(azimuth > 180.0, 360.0 - azimuth, azimuth)
    return np.round(azimuth, NODE_DECIMALS), np.round(radial, NODE_DECIMALS)


def measured_nodes(good: ReducedData, scatter_type: str, eta: float, isotropic: bool
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(incidence angles, their AngleOfIncidence, each point's block, azimuth, radial) in
    degrees of one side's points: the grid nodes a table needs to hold each at its own
    direction. Incidence must lie in the x-z plane, the source on -x (gonio's geometry,
    docs/architecture.md)."""
    if len(good.bsdf) == 0:
        raise CalibrationError(f"zemax: no valid {scatter_type} point to tabulate")
    if np.any(np.abs(good.wi[:, 1]) > 1e-9) or np.any(good.wi[:, 0] > 1e-12):
        raise CalibrationError("zemax: a measured table needs incidence in the x-z plane with "
                               "the source on -x (phi_i = 180 deg)")
    incidence, block = np.unique(np.round(good.theta_i_deg, 3), return_inverse=True)
    angle_deg = (incidence if scatter_type == "BRDF" else
                 np.degrees(np.arcsin(np.sin(np.radians(incidence)) / eta)))
    return (incidence, angle_deg, block,
            *_nodes(good, scatter_type, angle_deg, block, isotropic))


def measured_table(data: ReducedData, scatter_type: str, eta: float,
                   model_eval: Callable[[np.ndarray, np.ndarray], np.ndarray],
                   width_deg: float, isotropic: bool, comments: list[str],
                   model_name: str = "the fitted model") -> ZemaxTable:
    """The table of one side (BRDF | BTDF) of `data`'s valid points, filled by model_eval(wi,
    wo) (1/sr) where there is no data (the points' geometry: measured_nodes)."""
    good = data.subset(data.valid & (data.transmission == (scatter_type == "BTDF")))
    incidence, angle_deg, block, azimuth_at, radial_at = measured_nodes(good, scatter_type, eta,
                                                                        isotropic)
    azimuth = np.unique(np.concatenate([standard_azimuth(isotropic), azimuth_at]))
    radial = np.unique(np.concatenate([radial_grid(width_deg), radial_at]))
    n_az, n_rad = len(azimuth), len(radial)
    symmetry = "PlaneSymmetrical" if isotropic else "Asymmetrical"
    values = np.zeros((1, len(incidence), n_az, n_rad))
    tis = np.zeros((1, len(incidence)))
    notes = []
    for a, (ti, angle) in enumerate(zip(incidence, angle_deg, strict=True)):
        t = math.radians(ti)
        wi = np.array([-math.sin(t), 0.0, math.cos(t)]) + 0.0  # no -0 at normal incidence
        wo = scatter_directions(angle, scatter_type, azimuth, radial)
        inside = on_side(wo, scatter_type)
        sel = np.flatnonzero(block == a)
        coefficient, measured, interpolated = _cell_weights(azimuth_at[sel], radial_at[sel],
                                                            azimuth, radial)
        from_data = measured | interpolated
        data_cells = coefficient @ good.bsdf[sel]
        negative = int(np.sum(measured & (data_cells < 0)))
        model_cells = np.where(inside, model_eval(np.broadcast_to(wi, wo.shape), wo), 0.0)
        cells = np.where(from_data, np.maximum(data_cells, 0.0), model_cells)
        values[0, a] = cells
        weights = tis_weights(ZemaxTable(scatter_type, symmetry, np.zeros(1), angle_deg,
                                         azimuth, radial, values, tis), a)
        model_tis = hemisphere_integral(lambda w, wi=wi: model_eval(np.broadcast_to(wi, w.shape),
                                                                    w),
                                        scatter_type, angle, width_deg)
        tis[0, a] = float(np.sum(weights * cells))
        # the grid's quadrature error, as seen on the model: its sum against a fine rule
        u_grid = abs(float(np.sum(weights * model_cells)) - model_tis)
        points = good.subset(sel)
        u_data = _tis_uncertainty(points, np.tensordot(weights, coefficient, 2))
        u_interp = abs(float(np.sum(weights * interpolated * (coefficient @ model_eval(
            np.broadcast_to(wi, points.wo.shape), points.wo) - model_cells))))
        model_share = float(np.sum(weights * np.where(from_data, 0.0, model_cells)))
        u_fill = _fill_uncertainty(points, model_eval, wi, model_share)
        n_cells = int(inside.sum())
        notes.append(
            f"block AngleOfIncidence {angle:g} (theta_i {ti:g} deg): of its {n_cells} cells "
            f"measured {int(measured.sum())}, interpolated between them "
            f"{int((interpolated & inside).sum())}, {model_name} "
            f"{int((inside & ~from_data).sum())}"
            + (f"; {negative} negative measured values written as 0" if negative else "")
            + f"; TIS {tis[0, a]:.6g}, of it {model_share:.3g} from the model; standard "
            f"uncertainty +- {u_data:.2g} from the measured values, +- {u_interp:.2g} from "
            f"interpolation, +- {u_fill:.2g} from the model fill, +- {u_grid:.2g} from the "
            f"grid's quadrature, combined +- "
            f"{math.sqrt(u_data**2 + u_interp**2 + u_fill**2 + u_grid**2):.2g}")
    return ZemaxTable(scatter_type, symmetry, np.zeros(1), angle_deg, azimuth, radial, values, tis,
                      [*comments, *notes], "Measured")


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
    return coefficient, measured, interpolated


def _fill_uncertainty(points: ReducedData, model_eval: Callable[[np.ndarray, np.ndarray],
                                                                 np.ndarray],
                      wi: np.ndarray, model_share: float) -> float:
    """Standard uncertainty of the modelled cells' share of a TIS: that share times the RMS
    relative difference between the model and the block's measured values (how far the model
    is seen to stray from the data where both are known)."""
    model = model_eval(np.broadcast_to(wi, points.wo.shape), points.wo)
    keep = model > 0
    if not keep.any():
        return 0.0
    return abs(model_share) * float(np.sqrt(np.mean((points.bsdf[keep] / model[keep] - 1.0) ** 2)))


def _tis_uncertainty(points: ReducedData, gradient: np.ndarray) -> float:
    """Standard uncertainty of sum(gradient * bsdf) from the points' own errors and the
    relative errors they share (ReducedData.shared_rel)."""
    own = np.sum((gradient * points.sigma_own) ** 2)
    shared = np.sum(((gradient * points.bsdf) @ points.shared_rel) ** 2)
    return float(math.sqrt(own + shared))
