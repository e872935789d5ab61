"""Exports of a run's fitted model: Zemax tabular BSDF and Mitsuba 3 material.

`write_model(run_dir, fmt, out_path)` reduces and fits the run (calibration.pipeline) and
writes the file(s)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from calibration.exports.mitsuba import material_parameters, write_mitsuba
from calibration.exports.zemax import tabulate, write_zemax
from calibration.fit import FitResult
from calibration.pipeline import fit_run
from calibration.reduced import ReducedData
from calibration.values import CalibrationError
from gonio.record import record_lines, run_record
from gonio.store import open_run


def _notes(result: FitResult, source: str, record: Sequence[str]) -> list[str]:
    """The fit in one line, then the run's record (gonio.record.record_lines)."""
    params = ", ".join(f"{n} = {v:.6g} +- {e:.2g}"
                       for n, v, e in zip(result.names, result.values, result.errors, strict=True))
    held = ("n/a" if result.chi2_dof_heldout is None else f"{result.chi2_dof_heldout:.3g}")
    return [f"gonio fit of {source}: {result.distribution} ({result.masking} masking), {params}, "
            f"eta = {result.eta:.6g}; chi2/dof fitted {result.chi2_dof_fit:.3g} "
            f"({result.n_fit} points), held out {held} ({result.n_heldout} points)",
            *record]


def zemax_files(data: ReducedData, result: FitResult, out_path: str | Path,
                source: str = "", record: Sequence[str] = ()) -> list[Path]:
    """Tabulate the fitted model (at a point, no aperture average) at the data's incidence
    angles: one file per measured side,
    the BTDF at out_path when transmission was measured, else the BRDF; the other side goes
    next to it as <stem>-BRDF<suffix>. `record`: the run's record lines, as header comments."""
    out_path = Path(out_path)
    theta_i = np.unique(np.round(data.theta_i_deg[data.valid], 3))
    if len(theta_i) == 0:
        raise CalibrationError("zemax: the data have no valid point to take incidences from")
    sides = [s for s, present in (("BTDF", data.transmission[data.valid].any()),
                                  ("BRDF", (~data.transmission[data.valid]).any())) if present]
    alpha = np.atleast_1d(result.alpha)
    width_deg = math.degrees(float(alpha.min()))
    notes = _notes(result, source, record) + [
        "AngleOfIncidence = specular reflection angle (BRDF) or refracted direct-transmission "
        "angle asin(sin(theta_i)/eta) (BTDF); incidence angles theta_i: "
        + " ".join(f"{t:g}" for t in theta_i)]
    model = result.model()

    def point_model(wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        return result.scale * model.eval(wi, wo)

    paths = []
    for k, side in enumerate(sides):
        path = out_path if k == 0 else out_path.with_name(f"{out_path.stem}-{side}"
                                                           f"{out_path.suffix}")
        table = tabulate(point_model, side, theta_i, result.eta, width_deg,
                         isotropic=alpha.size == 1 or alpha[0] == alpha[-1], comments=notes)
        paths.append(write_zemax(table, path))
    return paths


def mitsuba_file(result: FitResult, out_path: str | Path, source: str = "",
                 record: Sequence[str] = ()) -> Path:
    """The fitted material as a Mitsuba 3 scene fragment (`record`: the run's record lines, as
    comments)."""
    notes = _notes(result, source, record)
    if result.distribution == "phong":
        notes.append("Mitsuba 3 has no Phong distribution: written as Beckmann of the same alpha "
                     "(Walter's mapping)")
    if result.masking != "separable":
        notes.append(f"the fit preferred {result.masking} masking; Mitsuba uses separable Smith")
    material = material_parameters(result.distribution, result.alpha, result.eta, result.scale,
                                   result.k)
    return write_mitsuba(material, out_path, notes)


def write_model(run_dir: str | Path, fmt: str, out_path: str | Path) -> list[Path]:
    """Reduce and fit a run, then write its model as `fmt` (zemax | mitsuba); returns every
    file written (zemax with both sides measured: the main file, then the other side's)."""
    data, result = fit_run(run_dir)
    record = record_lines(run_record(open_run(run_dir)))
    if fmt == "zemax":
        return list(zemax_files(data, result, out_path, source=str(run_dir), record=record))
    return [mitsuba_file(result, out_path, source=str(run_dir), record=record)]
