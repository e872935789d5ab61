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
    on_side,
    radial_grid,
    scatter_directions,
    specular_frame,
    tis_weights,
)
from calibration.reduced import ReducedData
from calibration.values import CalibrationError

NODE_DECIMALS = 4  # grid nodes of measured angles, degrees


def _nodes(data: ReducedData, scatter_type: str, angle_deg: np.ndarray, block: np.ndarray,
           fold: bool) -> tuple[np.ndarray, np.ndarray]:
    """(azimuth, radial) in degrees of each point about its block's specular direction."""
    azimuth, radial = np.zeros(len(block)), np.zeros(len(block))
    for a, angle in enumerate(angle_deg):
        sel = block == a
        c, e0, e90 = specular_frame(angle, scatter_type)
        wo = data.wo[sel]
        radial[sel] = np.degrees(np.arccos(np.clip(wo @ c, -1.0, 1.0)))
        azimuth[sel] = np.mod(np.degrees(np.arctan2(wo @ e90, wo @ e0)), 360.0)
    azimuth = np.where(radial < 10.0 ** -NODE_DECIMALS, 0.0, azimuth)
    if fold:
        azimuth = np.where(azimuth > 180.0, 360.0 - azimuth, azimuth)
    return np.round(azimuth, NODE_DECIMALS), np.round(radial, NODE_DECIMALS)


def measured_table(data: ReducedData, scatter_type: str, eta: float,
                   model_eval: Callable[[np.ndarray, np.ndarray], np.ndarray],
                   width_deg: float, isotropic: bool, comments: list[str],
                   model_name: str = "the fitted model") -> ZemaxTable:
    """The table of one side (BRDF | BTDF) of `data`'s valid points, filled by model_eval(wi,
    wo) (1/sr) where there is no data. Incidence must lie in the x-z plane, the source on -x
    (gonio's geometry, docs/architecture.md)."""
    good = data.subset(data.valid & (data.transmission == (scatter_type == "BTDF")))
    if len(good.bsdf) == 0:
        raise CalibrationError(f"zemax: no valid {scatter_type} point to tabulate")
    if np.any(np.abs(good.wi[:, 1]) > 1e-9) or np.any(good.wi[:, 0] > 1e-12):
        raise CalibrationError("zemax: a measured table needs incidence in the x-z plane with "
                               "the source on -x (phi_i = 180 deg)")
    theta_i = np.round(good.theta_i_deg, 3)
    incidence, block = np.unique(theta_i, return_inverse=True)
    angle_deg = (incidence if scatter_type == "BRDF" else
                 np.degrees(np.arcsin(np.sin(np.radians(incidence)) / eta)))
    azimuth_at, radial_at = _nodes(good, scatter_type, angle_deg, block, isotropic)
    standard_azimuth = np.arange(0.0, 180.1, 10.0) if isotropic else np.arange(0.0, 360.0, 10.0)
    azimuth = np.unique(np.concatenate([standard_azimuth, azimuth_at]))
    radial = np.unique(np.concatenate([radial_grid(width_deg), radial_at]))
    n_az, n_rad = len(azimuth), len(radial)
    symmetry = "PlaneSymmetrical" if isotropic else "Asymmetrical"
    values = np.zeros((1, len(incidence), n_az, n_rad))
    tis = np.zeros((1, len(incidence)))
    notes = []
    for a, (ti, angle) in enumerate(zip(incidence, angle_deg, strict=True)):
        t = math.radians(ti)
        wi = np.array([-math.sin(t), 0.0, math.cos(t)])
        wo = scatter_directions(angle, scatter_type, azimuth, radial)
        inside = on_side(wo, scatter_type)
        # coefficient[z, r, j]: the weight of the block's point j in cell (z, r)
        sel = np.flatnonzero(block == a)
        z_of = np.searchsorted(azimuth, azimuth_at[sel])
        r_of = np.searchsorted(radial, radial_at[sel])
        coefficient = np.zeros((n_az, n_rad, len(sel)))
        measured = np.zeros((n_az, n_rad), bool)
        interpolated = np.zeros((n_az, n_rad), bool)
        for z in np.unique(z_of):
            row = np.flatnonzero(z_of == z)
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
        from_data = measured | interpolated
        data_cells = coefficient @ good.bsdf[sel]
        negative = int(np.sum(measured & (data_cells < 0)))
        cells = np.where(from_data, np.maximum(data_cells, 0.0), 0.0)
        modelled = inside & ~from_data  # the model is evaluated where it fills, only
        cells[modelled] = model_eval(np.broadcast_to(wi, (int(modelled.sum()), 3)),
                                     wo[modelled])
        values[0, a] = cells
        weights = tis_weights(ZemaxTable(scatter_type, symmetry, np.zeros(1), angle_deg,
                                         azimuth, radial, values, tis), a)
        tis[0, a] = float(np.sum(weights * cells))
        u_tis = math.hypot(*good.subset(sel).linear_uncertainty(
            np.tensordot(weights, coefficient, 2)))
        notes.append(
            f"block AngleOfIncidence {angle:g} (theta_i {ti:g} deg): measured at "
            f"{int(measured.sum())} cells, interpolated between them at "
            f"{int(interpolated.sum())}, {model_name} at the other {int(modelled.sum())}"
            + (f"; {negative} negative measured values written as 0" if negative else "")
            + f"; TIS {tis[0, a]:.6g} +- {u_tis:.2g} (standard uncertainty from the measured "
            "values; the modelled cells' share without its uncertainty)")
    return ZemaxTable(scatter_type, symmetry, np.zeros(1), angle_deg, azimuth, radial, values, tis,
                      [*comments, *notes], "Measured")

