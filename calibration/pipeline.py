"""From a run directory to calibrated reduced data and a fit: apply the calibration the run
records (or one given), reduce (calibration.reduce), fit. What `gonio fit`, `gonio plot --fit`
and `gonio export --format zemax|mitsuba` share."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from calibration import calfile
from calibration.fit import FitError, FitOptions, FitResult, select
from calibration.reduced import ReducedData
from calibration.values import CalibrationError

if TYPE_CHECKING:
    from gonio.store import Run

#: The fit whose model gives `reduce_run` the BSDF's slope: the default one, made over every
#: valid point by `slope_fit_options`.
DEFAULT_SLOPE_FIT = FitOptions()
#: The slope fit's multiple-scattering term walks the fit's ms_walks // this (its walks are
#: forward, common to the nearby angles whose readings the slope differences).
SLOPE_FIT_WALKS_SHARE = 8
#: meta["budget"]["angle_terms"] and the note of a reduction asked to leave them out.
ANGLE_TERMS_EXCLUDED = ("angle: excluded (--no-angle-terms): U excludes the stages' "
                        "repeatability and the calibration's angle offsets")


def slope_fit_options(options: FitOptions) -> FitOptions:
    """A fit's options as the slope fit takes them: over every valid point, each incidence
    the run has (a run without normal incidence has its slope too), for the slope only
    (FitOptions.ms_slope_only, ms_walks // SLOPE_FIT_WALKS_SHARE walks: the budget needs the
    model's slope, not alpha's last digits)."""
    return replace(options, fit_incidence_deg=None, ms_slope_only=True,
                   ms_walks=max(2, options.ms_walks // SLOPE_FIT_WALKS_SHARE))


def calibration_for(meta: dict, calibration_file: str | Path | None) -> calfile.Calibration | None:
    """The calibration to apply: the file given, else the one the run records, else none."""
    if calibration_file is not None:
        return calfile.load(calibration_file)
    return calfile.used_by(meta)


def reduce_run(run: str | Path | Run, calibration_file: str | Path | None = None,
               shot_noise_w: float | None = None, subtract_signature: bool = False,
               signature_share: float | None = None,
               slope_options: FitOptions | None = DEFAULT_SLOPE_FIT,
               angle_terms: bool = True) -> ReducedData:
    """Calibrated ReducedData of a run (its directory, or the Run already open, whose readings
    are then read once; the calibration's name goes into meta["calibration"],
    the [optics] beam divergence into meta["beam_divergence_deg"] for the fit; an all-emulated
    run's [sim] table is meta["sim"], calibration.reduce; whether the run is complete is
    meta["completeness"], gonio.completeness). shot_noise_w: the --shot-noise-w
    flag (calibration.reduce.optics_of); subtract_signature: subtract the bench's own scatter
    that the run's signature readings measured, signature_share: the share of the net signal
    above which a point is flagged (calibration.signature; None: its default);
    slope_options, angle_terms: the fit whose model carries the angle errors into the budget,
    and whether to (`reduce_stored`)."""
    from gonio.completeness import completeness_of
    from gonio.store import Run, open_run

    if not isinstance(run, Run):
        run = open_run(run)
    readings = run.readings()
    data = reduce_stored(run, readings, calibration_file, shot_noise_w, subtract_signature,
                         signature_share, slope_options, angle_terms)
    data.meta["completeness"] = completeness_of(run, len(readings)).to_json()
    return data


def reduce_stored(run: Run, readings: np.ndarray, calibration_file: str | Path | None = None,
                  shot_noise_w: float | None = None, subtract_signature: bool = False,
                  signature_share: float | None = None, slope_options: FitOptions | None = None,
                  angle_terms: bool = True) -> ReducedData:
    """`reduce_run` of some of a run's stored readings (READING_DTYPE): those stored so far,
    for the live view of a run in progress. When the run has angle uncertainties (the
    stages' repeatability, the calibration's offsets) and slope_options are given, the data
    are fitted with them over every valid point (each incidence; the families the sample's
    kind allows, calibration.fit.select) and reduced again with the fitted model's slope in
    the budget (meta["budget"]["slope"] names the fit's family and distribution); a failed fit
    raises CalibrationError, unless angle_terms is False (--no-angle-terms: no fit, and
    meta["budget"]["angle_terms"] and its notes say that U excludes them). slope_options
    None (the live view): no fit, no angle terms, a note says so."""
    from calibration.budget import AngleInputs
    from calibration.reduce import optics_of, reduce_readings
    from gonio.record import emulator_config

    cal = calibration_for(run.meta, calibration_file)
    if cal is not None:
        readings = calfile.apply(readings, cal)
    optics = optics_of(run.config, cal, run.plan, emulator_config(run), shot_noise_w)
    share = {} if signature_share is None else {"signature_share": signature_share}
    angle = AngleInputs.of_run(run.config, cal)

    def reduced(slope_model=None) -> ReducedData:
        """The reduction, with the angle terms from slope_model if given."""
        data = reduce_readings(run, readings, cal, optics, subtract_signature=subtract_signature,
                               angle=angle, slope_model=slope_model, **share)
        if optics.optics is not None:
            data.meta["beam_divergence_deg"] = optics.optics.divergence_deg
        if cal is not None:
            data.meta["calibration"] = (str(calibration_file) if calibration_file is not None
                                        else run.meta.get("calibration"))
        return data

    data = reduced()
    if not angle.any or slope_options is None:
        return data
    if not angle_terms:
        budget = data.meta["budget"]
        budget["notes"] = [n for n in budget["notes"] if not n.startswith("angle:")]
        budget["notes"].append(ANGLE_TERMS_EXCLUDED)
        budget["angle_terms"] = "excluded"
        return data
    try:
        result = select(data, slope_fit_options(slope_options))
    except FitError as exc:
        raise CalibrationError(f"cannot estimate the budget's angle terms: the fit of the "
                               f"model's slope failed ({exc}); --no-angle-terms reduces "
                               f"with U excluding them") from None
    data = reduced(result.predict)
    data.meta["budget"]["slope"] = {"family": result.family, "distribution": result.distribution,
                                    "parameters": result.to_dict()["parameters"],
                                    "chi2_dof": result.chi2_dof_fit}
    data.meta["budget"]["notes"] += slope_fit_notes(result)
    return data


def slope_fit_notes(result: FitResult) -> list[str]:
    """A note when the fit that gave the angle terms' slope does not describe the data
    (chi2/dof above calibration.fit.result.MAX_CHI2_DOF): its slope is not the data's, so
    the angle terms may be too small or too large; the reduction goes on (a single-scattering
    fit of a multiply scattering sample is such a fit)."""
    from calibration.fit.result import MAX_CHI2_DOF

    if not result.chi2_dof_fit > MAX_CHI2_DOF:
        return []
    model = result.distribution if result.family == "microfacet" else result.family
    return [f"angle: the slope fit ({model}) has chi2/dof "
            f"{result.chi2_dof_fit:.3g} > {MAX_CHI2_DOF:g}: the angle terms come from a model "
            "that does not describe the data"]


def fit_run(run_dir: str | Path | Run, options: FitOptions | None = None,
            calibration_file: str | Path | None = None, shot_noise_w: float | None = None,
            subtract_signature: bool = False,
            progress: Callable[[str], None] | None = None,
            angle_terms: bool = True) -> tuple[ReducedData, FitResult]:
    """Reduce and fit a run (fitted twice when the angle terms need the model's slope, the
    same options over every incidence: `reduce_stored`; progress: calibration.fit.fit's
    progress lines; angle_terms: False for --no-angle-terms)."""
    options = options or FitOptions()
    data = reduce_run(run_dir, calibration_file, shot_noise_w, subtract_signature,
                      slope_options=options, angle_terms=angle_terms)
    return data, select(data, options, progress)

