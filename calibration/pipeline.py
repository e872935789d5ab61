"""From a run directory to calibrated reduced data and a fit: apply the calibration the run
records (or one given), reduce (calibration.reduce), fit. What `gonio fit`, `gonio plot --fit`
and `gonio export --format zemax|mitsuba` share."""

from __future__ import annotations

from pathlib import Path

from calibration import calfile
from calibration.fit import FitOptions, FitResult, fit
from calibration.reduced import ReducedData


def calibration_for(meta: dict, calibration_file: str | Path | None) -> calfile.Calibration | None:
    """The calibration to apply: the file given, else the one the run records, else none."""
    if calibration_file is not None:
        return calfile.load(calibration_file)
    return calfile.used_by(meta)


def reduce_run(run_dir: str | Path, calibration_file: str | Path | None = None,
               shot_noise_w: float | None = None) -> ReducedData:
    """Calibrated ReducedData of a run (the calibration's name goes into meta["calibration"],
    the [optics] beam divergence into meta["beam_divergence_deg"] for the fit; an all-emulated
    run's [sim] table is meta["sim"], calibration.reduce). shot_noise_w: the --shot-noise-w
    flag (calibration.reduce.optics_of)."""
    from calibration.reduce import optics_of, reduce_readings
    from gonio.record import emulator_config
    from gonio.store import open_run

    run = open_run(run_dir)
    readings = run.readings()
    cal = calibration_for(run.meta, calibration_file)
    if cal is not None:
        readings = calfile.apply(readings, cal)
    optics = optics_of(run.config, cal, run.plan, emulator_config(run), shot_noise_w)
    data = reduce_readings(run, readings, cal, optics)
    if optics.optics is not None:
        data.meta["beam_divergence_deg"] = optics.optics.divergence_deg
    if cal is not None:
        data.meta["calibration"] = (str(calibration_file) if calibration_file is not None
                                    else run.meta.get("calibration"))
    return data


def fit_run(run_dir: str | Path, options: FitOptions | None = None,
            calibration_file: str | Path | None = None, shot_noise_w: float | None = None
            ) -> tuple[ReducedData, FitResult]:
    """Reduce and fit a run."""
    data = reduce_run(run_dir, calibration_file, shot_noise_w)
    return data, fit(data, options)

