"""`gonio calibrate`: build a calibration file from calibration runs, record one in a run, show
one. `build RUN [RUN...] --out CAL.json [--eta N] [--aperture-geometry D_MM DIST_MM |
--aperture-scan RUN] [--reference CERT.toml] [--force]`; `use RUN CAL.json`; `show CAL.json`.
Each RUN serves what its plan's `calibrates` says (calibration.routing), a reference panel's run
the reference whose certificate --reference gives; the aperture, the beam and its divergence
come from the runs' [optics] where no option gives them; build says on stderr, one line each,
what it could not calibrate, and refuses a fit the model does not describe unless --force."""

from __future__ import annotations

import argparse
import json
import sys
from typing import TYPE_CHECKING

from gonio_cli.incomplete import add_force_option

if TYPE_CHECKING:
    import numpy as np

    from calibration.calfile import Calibration
    from calibration.certificate import Certificate
    from calibration.reference import ReferenceScale
    from calibration.values import Measured
    from gonio.store import Run


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the `calibrate` verb and its actions."""
    p = subparsers.add_parser("calibrate", help="detector, beam, angle and aperture calibration",
                              description=__doc__)
    actions = p.add_subparsers(dest="action", metavar="ACTION")
    actions.required = True
    b = actions.add_parser("build", help="calibration file from calibration runs")
    b.add_argument("runs", nargs="+", metavar="RUN", help="calibration run directories, each "
                   "used for what its plan calibrates (angles, aperture, detector; darks from "
                   "all)")
    b.set_defaults(reads_run=("runs", "aperture_scan"))
    b.add_argument("--out", required=True, metavar="FILE", help="calibration file (.json)")
    b.add_argument("--eta", type=float, help="sample eta: also find the angle zero offsets "
                   "from the transmitted and specular peaks in the angle runs (default: their "
                   "[sample] eta)")
    group = b.add_mutually_exclusive_group()
    group.add_argument("--aperture-geometry", nargs=2, type=float, metavar=("D_MM", "DIST_MM"),
                       help="aperture diameter and distance from the sample, mm (default: "
                       "the runs' [optics] aperture_diameter_mm and aperture_distance_mm)")
    group.add_argument("--aperture-scan", metavar="RUN",
                       help="run with an arm scan across the straight beam (sample retracted; "
                       "a RUN whose plan calibrates the aperture is one)")
    b.add_argument("--beam-diameter-mm", type=float,
                   help="beam diameter at the aperture for --aperture-scan (default: the "
                   "run's [optics] beam_diameter_mm widened by divergence_deg over "
                   "aperture_distance_mm; 0, a beam much smaller, without them)")
    b.add_argument("--reference", metavar="CERT.toml",
                   help="certificate of the reference panel that one RUN measures (its [sample] "
                   'kind = "reference"): runs reduced with the calibration are normalised to '
                   "it and carry the certificate's uncertainty (docs/calibration.md)")
    b.add_argument("--divergence-deg", type=_half_angle_deg, metavar="DEG",
                   help="beam divergence half-angle for the angle-offset fit (default: the "
                   "runs' [optics] divergence_deg, else 0)")
    add_force_option(b, also="; and write a fit with chi2/dof above 3, or angle offsets from a "
                             "sample its plan does not name a reference for them, with a "
                             "warning")
    u = actions.add_parser("use", help="record in a run which calibration applies to it")
    u.add_argument("run", help="run directory")
    u.add_argument("calibration", help="calibration file")
    s = actions.add_parser("show", help="print a calibration file's values")
    s.add_argument("calibration", help="calibration file")
    p.set_defaults(func=run)


def _half_angle_deg(text: str) -> float:
    """A beam divergence half-angle from the command line: a number in [0, 45) degrees."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not 0.0 <= value < 45.0:
        raise argparse.ArgumentTypeError(f"a half-angle in [0, 45) deg, got {value:g}")
    return value


def run(args: argparse.Namespace) -> int:
    """Dispatch to the action."""
    if args.action == "build":
        return _build(args)
    if args.action == "use":
        return _use(args)
    from calibration import calfile

    print(json.dumps(calfile.load(args.calibration).to_json(), indent=2))
    return 0


def _build(args: argparse.Namespace) -> int:
    from calibration import calfile
    from calibration.calibrate import build
    from calibration.certificate import load as load_certificate
    from calibration.routing import route
    from gonio.store import open_run, utc_now
    from gonio_cli.incomplete import incomplete_notes

    runs = [open_run(r, force=args.force) for r in args.runs]
    divergence = args.divergence_deg
    if divergence is None:
        divergence = _optics(runs, "divergence_deg") or 0.0
    readings = [r.readings() for r in runs]
    aperture_run = open_run(args.aperture_scan, force=args.force) if args.aperture_scan \
        else None
    certificate = load_certificate(args.reference) if args.reference else None
    routes = route(runs, readings, aperture_run, args.aperture_geometry is not None,
                   certificate is not None)
    angle_runs = [run for run, take in zip(runs, routes.angles, strict=True) if take]
    eta = args.eta if args.eta is not None else _sample_eta(angle_runs)
    cal = build(readings, utc_now(), [str(r.path) for r in runs],
                eta=eta, aperture=_aperture(args, runs, routes.aperture_scan),
                divergence_deg=divergence, angle_runs=routes.angles,
                reference=None if certificate is None
                else _reference(routes.reference, readings[runs.index(routes.reference)],
                                certificate))
    _refuse_or_warn(cal, angle_runs, args.force)
    for note in cal.notes:
        print(f"gonio calibrate: {note}", file=sys.stderr)
    # said on stderr before the build (gonio_cli.incomplete)
    cal.notes += incomplete_notes([*runs, *([aperture_run] if aperture_run else [])])
    print(calfile.save(cal, args.out))
    return 0


def _reference(run: Run, readings: np.ndarray, certificate: Certificate) -> ReferenceScale:
    """The reference calibration from the reference panel's run, reduced as `gonio reduce`
    reduces it (its own dark and beam readings, the calibration it records; no angle terms)."""
    from calibration.pipeline import reduce_stored
    from calibration.reference import scale_from
    from calibration.values import CalibrationError

    try:
        data = reduce_stored(run, readings, slope_options=None)
    except CalibrationError as exc:
        raise CalibrationError(f"{run.path}: the reference run: {exc}") from None
    return scale_from(data, certificate, str(run.path))


def _refuse_or_warn(cal: Calibration, angle_runs: list[Run], force: bool) -> None:
    """Refuse (one CalibrationError line) a part whose fit has chi2/dof above CHI2_DOF_WARN,
    or angle offsets from a sample its plan does not name a reference for the angles; with
    --force add a warning note for the second (the first has its note already)."""
    from calibration.calibrate import CHI2_DOF_WARN, FITS, bad_fits
    from calibration.values import CalibrationError

    problems = [f"{part}: the {FITS[part]} fit has chi2/dof {chi2:.3g} > {CHI2_DOF_WARN:g} "
                "(the model misses the readings by more than their noise)"
                for part, chi2 in bad_fits(cal).items()]
    if cal.angle_fit is not None and (unnamed := _not_angle_references(angle_runs)):
        text = (f"angles: the [sample] of {unnamed} is not named a reference for them "
                '([sample] reference = "angles": a smooth or mirror sample whose model fits '
                "the peaks)")
        problems.append(text)
        if force:
            cal.notes.append(text.replace("angles: ", "angles: warning: ", 1))
    if problems and not force:
        raise CalibrationError("; ".join(problems) + ": nothing written (--force writes it)")


def _not_angle_references(angle_runs: list[Run]) -> str:
    """The angle runs whose plan's [sample] is not named an angle reference, listed ('' if
    none)."""
    from gonio.sample import sample_of_plan

    return ", ".join(str(run.path) for run in angle_runs
                     if getattr(sample_of_plan(run.plan, str(run.path)), "reference", "")
                     != "angles")


def _sample_eta(angle_runs: list[Run]) -> float | None:
    """The reference sample's index for the angle offsets when --eta is not given: the [sample]
    eta of the angle runs that state one, if they agree (else None)."""
    from calibration.values import CalibrationError
    from gonio.sample import sample_of_plan

    etas = {str(run.path): sample.eta for run in angle_runs
            if (sample := sample_of_plan(run.plan, str(run.path))) is not None
            and sample.eta is not None}
    if len(set(etas.values())) > 1:
        raise CalibrationError("the specular scans' [sample] eta differ ("
                               + ", ".join(f"{v:g} in {p}" for p, v in etas.items())
                               + "): give the reference sample's --eta")
    return next(iter(etas.values()), None)


def _optics(runs: list[Run], key: str) -> float | None:
    """A value of the runs' [optics] tables (None where they have none); the one place the
    calibrate command reads [optics]. Runs that disagree on it cannot be calibrated together."""
    from calibration.values import CalibrationError

    values = {str(r.path): (r.config.get("optics") or {}).get(key) for r in runs}
    if len(set(values.values())) > 1:
        raise CalibrationError(f"the runs' [optics] {key} differ ("
                               + ", ".join(f"{v} in {p}" for p, v in values.items())
                               + "): calibrate each bench set-up on its own")
    value = next(iter(values.values()))
    return None if value is None else float(value)


def _aperture(args: argparse.Namespace, runs: list[Run], scan: Run | None
              ) -> tuple[Measured, Measured, str] | None:
    """(solid angle, half-angle, method): measured from the aperture scan (--aperture-scan, or
    a RUN whose plan calibrates the aperture), else from --aperture-geometry or the runs'
    [optics] aperture_diameter_mm and aperture_distance_mm, the half-angle's sigma from the
    diameter's tolerance (calibration.type_b); None without any of them."""
    import math

    from calibration import aperture
    from calibration.type_b import half_angle_sigma_deg
    from calibration.values import Measured

    if scan is not None:
        named = "--aperture-scan" if args.aperture_scan else "aperture scan"
        return (*_aperture_from_scan(scan, named, args.beam_diameter_mm, args.divergence_deg),
                "beam-scan")
    diameter_mm, distance_mm = args.aperture_geometry or (
        _optics(runs, "aperture_diameter_mm"), _optics(runs, "aperture_distance_mm"))
    if diameter_mm is None or distance_mm is None:
        return None
    omega = aperture.from_geometry(0.5e-3 * diameter_mm, 1e-3 * distance_mm)
    half = math.degrees(math.atan2(0.5 * diameter_mm, distance_mm))
    tolerance = None if args.aperture_geometry else _optics(runs, "aperture_diameter_tolerance_mm")
    return (Measured(omega, 0.0),  # a nominal aperture: reduction counts its tolerance itself
            Measured(half, half_angle_sigma_deg(diameter_mm, distance_mm, tolerance)),
            "geometry")


def _aperture_from_scan(scan_run: Run, named: str, beam_diameter_mm: float | None,
                        divergence_deg: float | None) -> tuple[Measured, Measured]:
    """(solid angle, half-angle) from the sample readings of a scan across the beam; the beam's
    diameter at the aperture is --beam-diameter-mm, else the scan run's [optics] beam diameter
    widened by the divergence (--divergence-deg, else its [optics]) over the aperture
    distance, else 0 (much smaller)."""
    import math

    import numpy as np

    from calibration import aperture
    from calibration.detector import correct_power, dark_offsets
    from calibration.routing import role_hint
    from calibration.values import CalibrationError

    where = f"{named} {scan_run.path}"
    distance_mm = _optics([scan_run], "aperture_distance_mm")
    if beam_diameter_mm is None:
        beam_mm = _optics([scan_run], "beam_diameter_mm")
        if divergence_deg is None:
            divergence_deg = _optics([scan_run], "divergence_deg") or 0.0
        beam_diameter_mm = 0.0 if beam_mm is None or distance_mm is None else (
            beam_mm + 2.0 * distance_mm * math.tan(math.radians(divergence_deg)))
    beam_rad = 0.0
    if beam_diameter_mm > 0:
        if distance_mm is None:
            raise CalibrationError(f"{where}: --beam-diameter-mm needs the aperture distance "
                                   "([optics] aperture_distance_mm) in the run's config")
        beam_rad = 0.5 * beam_diameter_mm / distance_mm
    r = scan_run.readings()
    sample = r[r["kind"] == "sample"]
    try:
        if len(sample) == 0:
            raise CalibrationError("no sample readings to scan the beam with")
        angles = np.unique(np.round(sample["sample_deg"], 3))
        if len(angles) > 1:
            raise CalibrationError(f"its sample readings are at {len(angles)} sample angles, "
                                   "not a scan of the arm alone across the beam with the "
                                   "sample retracted (examples/plans/calib-aperture.toml)")
        power = correct_power(sample["power_w"], sample["range_w"], dark_offsets(r), None)
        low = power < 0.02 * power.max()
        noise = np.std(power[low]) if np.any(low) else 0.0
        sigma = np.hypot(noise, 1e-3 * np.abs(power))
        return aperture.from_beam_scan(sample["arm_deg"], power, sigma,
                                       beam_radius_rad=beam_rad)
    except CalibrationError as exc:
        raise CalibrationError(f"{where}: {exc}{role_hint(scan_run)}") from None


def _use(args: argparse.Namespace) -> int:
    from calibration import calfile
    from gonio.store import META, open_run, write_json_atomic

    run = open_run(args.run)
    meta = dict(run.meta)
    meta["calibration"] = calfile.reference(args.calibration)
    write_json_atomic(run.path / META, meta)
    print(f"{run.path}: calibration {meta['calibration']['file']}")
    return 0
