"""Build a calibration from the readings of calibration runs (examples/plans/calib-*.toml).

What each part needs in the readings (several runs may be given together):
- detector: dark readings on every range used; for gains, the same points read on different
  fixed ranges: one run of a plan whose grid steps through ranges (calib-detector.toml), or
  runs each on one fixed range; a drift within a run is taken out by its beam readings;
- angles: a transmission scan across the refracted peak at normal incidence and a reflection
  scan across the specular peak at one or more sample angles, each point repeated (the scatter
  of repeats is the readings' noise);
- beam: the interleaved straight-through readings (a summary of drift and noise);
- reference: a certified panel's run, reduced and divided by its certificate
  (calibration.reference, made by the command line, which reduces runs).

Angles (architecture.md geometry, true = reported + offset, eta of the sample): the transmitted
peak at reported sample 0 sits near reported arm 180 + ds (1 - 1/eta) - da, the specular peak at
reported sample S near 2 (S + ds) - da; two peaks give ds and da, fitted with the reference
sample's microfacet model (calibration.angles).
"""

from __future__ import annotations

import numpy as np

from calibration import angles as angle_cal
from calibration.beam import beam_power
from calibration.calfile import Calibration
from calibration.detector import (
    correct_power,
    correction_sigma_w,
    dark_for,
    dark_offsets,
    gain_ratios,
    pooled_sem,
    range_key,
    ranges_read_together,
)
from calibration.reference import ReferenceScale
from calibration.routing import holds_specular_scan
from calibration.values import CalibrationError, Measured
from gonio.reading_flags import INVALID, flagged

STAGES = ("sample", "arm", "elevation", "azimuth")  # PeakScan's stage order
# chi2/dof above which a fit is reported as bad: the 99.9 % point of chi2/dof at 10 degrees of
# freedom (2.96), the fewest a calibration fit gets from the calib-*.toml plans (they give tens
# to hundreds), so a right model under honest noise stays below it. Above it the model misses
# the readings (a peak outside its scan, source drift, a nonlinear range, noise underestimated);
# the fits scale their sigmas by sqrt(chi2/dof), which does not cover a biased value.
CHI2_DOF_WARN = 3.0
#: The parts of a calibration made by a fit with a chi2/dof, and what each fit is called.
FITS = {"gains": "gain", "angles": "zero-offset", "reference": "reference-scale"}


def averaged_points(rows: np.ndarray, side: str, common_w: np.ndarray | None = None
                    ) -> angle_cal.PeakScan:
    """Average the repeats of each plan point (at least two each) of one scan; their standard
    errors from the noise law pooled over the scan (detector.pooled_sem, with each point's
    range: an autoranged scan's read noise follows the range), with the errors the repeats
    share (`common_w`, per row: the dark offset's and gain's, beam_normalised) added."""
    groups, where, full_scale, common = [], [], [], []
    for p in np.unique(rows["point"]):
        at = rows["point"] == p
        sel = rows[at]
        if len(sel) < 2:
            raise CalibrationError(f"point {int(p)}: angle calibration needs repeated readings "
                                   "(set repeats >= 2 in the plan) to know their noise")
        groups.append(np.asarray(sel["power_w"], dtype=np.float64))
        where.append([float(sel[f"{role}_deg"].mean()) for role in STAGES])
        full_scale.append(float(sel["range_w"].max()))
        common.append(0.0 if common_w is None else float(common_w[at].mean()))
    stages = np.array(where).T
    sem = pooled_sem(groups, np.array(full_scale))
    return angle_cal.PeakScan(side, *stages, np.array([g.mean() for g in groups]),
                              np.hypot(sem, common))


def peak_scans(readings: np.ndarray, common_w: np.ndarray | None = None
               ) -> list[angle_cal.PeakScan]:
    """The transmitted scan at normal incidence and each specular scan (one per reported sample
    angle) in the sample readings, their repeats averaged (common_w: as averaged_points, one
    per reading)."""
    sample = readings["kind"] == "sample"
    rows = readings[sample]
    common = None if common_w is None else common_w[sample]
    trans = (rows["side"] == "transmission") & (np.abs(rows["sample_deg"]) < 0.5)
    refl = rows["side"] == "reflection"
    if not trans.any() or not refl.any():
        raise CalibrationError("angle calibration needs a transmission scan at normal incidence "
                               "and a reflection scan across the specular peak")

    def scan(select: np.ndarray, side: str) -> angle_cal.PeakScan:
        return averaged_points(rows[select], side, None if common is None else common[select])

    scans = [scan(trans, "transmission")]
    for s in np.unique(np.round(rows["sample_deg"][refl], 3)):
        scans.append(scan(refl & (np.abs(rows["sample_deg"] - s) < 1e-3), "reflection"))
    return scans


def angle_offsets(readings: np.ndarray, eta: float, aperture_half_angle_deg: float = 0.0,
                  divergence_deg: float = 0.0, common_w: np.ndarray | None = None,
                  aperture_sigma_deg: float = 0.0) -> angle_cal.OffsetFit:
    """Sample and arm offsets (degrees) from the transmitted peak at normal incidence and the
    specular peak(s) in the readings (sample readings; powers already dark-corrected and
    beam-normalised, common_w their shared errors as beam_normalised gives them), by the
    model fit of calibration.angles (the aperture's half-angle fitted within
    aperture_sigma_deg when that is > 0)."""
    return angle_cal.fit_offsets(peak_scans(readings, common_w), eta, aperture_half_angle_deg,
                                 divergence_deg, aperture_sigma_deg)


def covering(gains: dict[str, Measured] | None,
             readings: np.ndarray) -> dict[str, Measured] | None:
    """The gains, with gain 1 for the readings' ranges that the gain runs did not cover (the
    best available for those ranges when building a calibration)."""
    if gains is None:
        return None
    return {**{range_key(r): Measured(1.0, 0.0) for r in np.unique(readings["range_w"])},
            **gains}


def beam_normalised(readings: np.ndarray, darks: dict[str, Measured],
                    gains: dict[str, Measured] | None) -> tuple[np.ndarray, np.ndarray]:
    """Readings with dark- and gain-corrected power (gain 1 on ranges the gains do not cover),
    divided by the beam power at each reading's time (BeamPower.smooth_at) when the run has
    unsaturated beam readings (a drift during a peak scan would otherwise skew the peak and
    bias its centre; an over-range reading is clipped); and each normalised power's sigma from
    the dark offset and gain of its range (detector.correction_sigma_w, normalised alike)."""
    out = readings.copy()
    gains = covering(gains, readings)
    out["power_w"] = correct_power(readings["power_w"], readings["range_w"], darks, gains)
    common = correction_sigma_w(out["power_w"], readings["range_w"], darks, gains)
    beam = (out["kind"] == "beam") & ~out["saturated"]
    if beam.any():
        model = beam_power(out["t_s"][beam], out["power_w"][beam])
        level = model.smooth_at(out["t_s"])[0]
        out["power_w"] = out["power_w"] / level
        common = common / level
    return out, common


def drift_free(run: np.ndarray, darks: dict[str, Measured]) -> np.ndarray:
    """A run's readings with each sample reading's net power (reading less its range's dark
    offset) rescaled by mean beam / beam at its time (BeamPower.smooth_at), when the run has
    unsaturated beam readings; else the readings as they are. Gains are ratios of readings
    taken at different times: a drift between them would enter the gains."""
    beam = (run["kind"] == "beam") & ~run["saturated"]
    if beam.sum() < 2:
        return run
    net_beam = correct_power(run["power_w"][beam], run["range_w"][beam], darks, None)
    model = beam_power(run["t_s"][beam], net_beam)
    out = run.copy()
    sample = out["kind"] == "sample"
    dark = np.array([dark_for(darks, r).value for r in out["range_w"][sample]])
    factor = model.mean_w / model.smooth_at(out["t_s"][sample])[0]
    out["power_w"][sample] = dark + (out["power_w"][sample] - dark) * factor
    return out


def beam_summary(readings: np.ndarray, darks: dict[str, Measured] | None,
                 gains: dict[str, Measured] | None) -> dict[str, float] | None:
    """Mean, relative drift and noise of the (corrected, unsaturated) beam readings, if any."""
    beam = readings[(readings["kind"] == "beam") & ~readings["saturated"]]
    if len(beam) == 0:
        return None
    power = beam["power_w"]
    if darks is not None:
        power = correct_power(power, beam["range_w"], darks, covering(gains, beam))
    model = beam_power(beam["t_s"], power)
    return {"readings": int(len(beam)), "mean_w": model.mean_w, "drift_rms": model.drift_rms,
            "noise_w": model.noise_w, "interpolation_rel": model.interp_rel}


def detector_notes(readings: np.ndarray, darks: dict[str, Measured],
                   gains: dict[str, Measured] | None) -> list[str]:
    """What the detector part lacks, one line each: ranges that sample or beam readings use with
    no dark readings of their own, or with no gain."""
    used = {range_key(r) for r in readings["range_w"][readings["kind"] != "dark"]}
    notes = []
    if no_dark := sorted(used - set(darks), key=float):
        notes.append(f"darks: none on {_ranges_text(no_dark)}, which sample or beam readings "
                     "use: reduction takes the nearest range's offset (let each dark slot read "
                     "every range, as examples/plans/calib-detector.toml does)")
    if gains is None:
        notes.append("gains: not calibrated: no run reads the same positions on two ranges or "
                     "more (a grid stepping through ranges, as examples/plans/calib-detector.toml)")
    elif no_gain := sorted(used - set(gains), key=float):
        notes.append(f"gains: not calibrated on {_ranges_text(no_gain)}: no position was read "
                     "with enough signal on it and on another range")
    return notes


def fit_chi2_dof(cal: Calibration) -> dict[str, float]:
    """{part: chi2/dof} of the calibration's fits (FITS) that were made."""
    fits = {"gains": cal.linearity, "angles": cal.angle_fit,
            "reference": None if cal.reference is None else cal.reference.to_json()}
    return {part: float(fit["chi2_dof"]) for part, fit in fits.items() if fit is not None}


def bad_fits(cal: Calibration) -> dict[str, float]:
    """{part: chi2/dof} of the fits whose chi2/dof exceeds CHI2_DOF_WARN: the model misses the
    readings, and the values may be biased (`gonio calibrate build` refuses them)."""
    return {part: chi2 for part, chi2 in fit_chi2_dof(cal).items() if chi2 > CHI2_DOF_WARN}


def fit_warning(part: str, chi2_dof: float) -> list[str]:
    """A warning line if a fit's chi2/dof exceeds CHI2_DOF_WARN, else none."""
    if chi2_dof <= CHI2_DOF_WARN:
        return []
    return [f"{part}: warning: the {FITS[part]} fit has chi2/dof {chi2_dof:.3g} > "
            f"{CHI2_DOF_WARN:g}: the model misses the readings by more than their noise (its "
            "sigmas are scaled by sqrt(chi2/dof), but its values may be biased)"]


def _ranges_text(keys: list[str]) -> str:
    return ("range " if len(keys) == 1 else "ranges ") + ", ".join(f"{k} W" for k in keys)


def build(runs: list[np.ndarray], created_utc: str, source_runs: list[str],
          eta: float | None = None, aperture: tuple[Measured, Measured, str] | None = None,
          divergence_deg: float = 0.0, angle_runs: list[bool] | None = None,
          reference: ReferenceScale | None = None) -> Calibration:
    """Everything the runs' readings (one array per run) can determine: darks always; gains
    from the runs that read stage positions on several ranges, or on one fixed range each
    (an autoranged run reads a position on one range only);
    angle offsets, when eta is given, from the runs angle_runs flags (default: those holding a
    specular scan, routing.holds_specular_scan), each normalised by its own beam readings
    (times restart with every run), modelled with the aperture (if given) and the beam's
    divergence half-angle; a beam summary per run; the reference calibration given (made from
    a reference run, calibration.reference). `notes` says what could not
    be calibrated and why, and which fit fits badly; a CalibrationError for what eta asks.
    Readings flagged invalid (the detector had none) are left out."""
    runs = [run[~flagged(run, INVALID)] for run in runs]
    readings = np.concatenate(runs)
    darks = dark_offsets(readings)
    cal = Calibration(created_utc=created_utc, source_runs=source_runs, dark_offsets_w=darks,
                      reference=reference)
    if reference is not None:
        cal.notes += fit_warning("reference", reference.chi2_dof)
    fixed = [drift_free(run, darks) for run in runs if ranges_read_together(run)
             or len(np.unique(run["range_w"][run["kind"] == "sample"])) == 1]
    fixed_readings = np.concatenate(fixed) if fixed else readings[:0]
    if ranges_read_together(fixed_readings):
        gains = gain_ratios(fixed_readings, darks)
        cal.gains, cal.gain_reference = gains.gains, gains.reference
        cal.linearity = {"chi2_dof": gains.chi2_dof, "max_deviation": gains.max_deviation,
                         "exponents": {k: v.to_json() for k, v in gains.exponents.items()}}
    cal.notes += detector_notes(readings, darks, cal.gains)
    if cal.linearity is not None:
        cal.notes += fit_warning("gains", cal.linearity["chi2_dof"])
    if eta is None:
        cal.notes.append("angles: not calibrated: no eta of a reference sample (--eta, or the "
                         "[sample] of a run with a specular scan)")
    else:
        chosen = [holds_specular_scan(run) for run in runs] if angle_runs is None else angle_runs
        _angles(cal, [run for run, take in zip(runs, chosen, strict=True) if take], eta,
                aperture, divergence_deg)
    if aperture is None:
        cal.notes.append("aperture: not calibrated: no geometry (--aperture-geometry or the "
                         "runs' [optics]) and no beam scan (--aperture-scan) given")
    else:
        cal.aperture_solid_angle_sr, cal.aperture_half_angle_deg, cal.aperture_method = aperture
    summaries = [dict(run=name, **summary) for name, run in zip(source_runs, runs, strict=True)
                 if (summary := beam_summary(run, darks, cal.gains)) is not None]
    cal.beam = summaries or None
    cal.notes += [saturated_beam_note(name) for name, run in zip(source_runs, runs, strict=True)
                  if all_beam_saturated(run)]
    return cal


def all_beam_saturated(run: np.ndarray) -> bool:
    """Whether a run has beam readings and every one of them read over range."""
    beam = run["kind"] == "beam"
    return bool(beam.any() and run["saturated"][beam].all())


def saturated_beam_note(run_name: str) -> str:
    """The note on a run none of whose beam readings is below its range's full scale."""
    return (f"beam: every beam reading of {run_name} is saturated (over range), so none "
            "normalises it: give the plan's [beam] a range above the beam's power")


def _angles(cal: Calibration, runs: list[np.ndarray], eta: float,
            aperture: tuple[Measured, Measured, str] | None, divergence_deg: float) -> None:
    """The angle zero offsets into cal, from the runs given (each holding a specular scan)."""
    peak_runs, common = [], []
    for k, run in enumerate(runs):
        normalised, shared = beam_normalised(run, cal.dark_offsets_w, cal.gains)
        normalised["point"] += k * 10_000_000  # plan points are per run
        peak_runs.append(normalised)
        common.append(shared)
    if not peak_runs:
        raise CalibrationError("angle calibration (--eta) needs a run with a specular "
                               "scan (examples/plans/calib-angles.toml)")
    half_angle = Measured(0.0, 0.0) if aperture is None else aperture[1]
    offsets = angle_offsets(np.concatenate(peak_runs), eta, half_angle.value, divergence_deg,
                            np.concatenate(common), half_angle.sigma)
    cal.sample_offset_deg, cal.arm_offset_deg = offsets.sample_offset, offsets.arm_offset
    cal.angle_fit = {"distribution": offsets.distribution, "alpha": offsets.alpha.to_json(),
                     "chi2_dof": offsets.chi2_dof, "points": offsets.n_points,
                     "aperture_half_angle_deg": half_angle.value, "divergence_deg": divergence_deg}
    if offsets.aperture_half_angle is not None:  # the aperture the peaks say, within its prior
        cal.angle_fit["aperture_prior_deg"] = half_angle.to_json()
        cal.angle_fit["aperture_fitted_deg"] = offsets.aperture_half_angle.to_json()
    cal.notes += fit_warning("angles", offsets.chi2_dof)
