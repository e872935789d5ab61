"""`gonio calibrate`: build a calibration file from calibration runs, record one in a run, show
one. `build RUN [RUN...] --out CAL.json [--eta N] [--aperture-geometry D_MM DIST_MM |
--aperture-scan RUN]`; `use RUN CAL.json`; `show CAL.json`."""

from __future__ import annotations

import argparse
import json


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the `calibrate` verb and its actions."""
    p = subparsers.add_parser("calibrate", help="detector, beam, angle and aperture calibration",
                              description=__doc__)
    actions = p.add_subparsers(dest="action", metavar="ACTION")
    actions.required = True
    b = actions.add_parser("build", help="calibration file from calibration runs")
    b.add_argument("runs", nargs="+", metavar="RUN", help="calibration run directories")
    b.add_argument("--out", required=True, metavar="FILE", help="calibration file (.json)")
    b.add_argument("--eta", type=float, help="sample eta: also find the angle zero offsets "
                   "from the transmitted and specular peaks in the runs")
    group = b.add_mutually_exclusive_group()
    group.add_argument("--aperture-geometry", nargs=2, type=float, metavar=("D_MM", "DIST_MM"),
                       help="aperture diameter and distance from the sample, mm")
    group.add_argument("--aperture-scan", metavar="RUN",
                       help="run with an arm scan across the straight beam (sample retracted)")
    b.add_argument("--beam-diameter-mm", type=float, default=0.0,
                   help="beam diameter for --aperture-scan (default 0: beam much smaller)")
    b.add_argument("--divergence-deg", type=_half_angle_deg, metavar="DEG",
                   help="beam divergence half-angle for the angle-offset fit (default: the "
                   "run's [optics] divergence_deg, else 0)")
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
    import math

    from calibration import aperture, calfile
    from calibration.calibrate import build
    from calibration.values import Measured
    from gonio.store import open_run, utc_now

    runs = [open_run(r) for r in args.runs]
    ap = None
    if args.aperture_geometry:
        diameter_mm, distance_mm = args.aperture_geometry
        omega = aperture.from_geometry(0.5e-3 * diameter_mm, 1e-3 * distance_mm)
        half = math.degrees(math.atan2(0.5 * diameter_mm, distance_mm))
        ap = (Measured(omega, 0.0), Measured(half, 0.0), "geometry")
    elif args.aperture_scan:
        ap = (*_aperture_from_scan(open_run(args.aperture_scan), args.beam_diameter_mm),
              "beam-scan")
    divergence = args.divergence_deg
    if divergence is None:
        divergence = float((runs[0].config.get("optics") or {}).get("divergence_deg", 0.0))
    cal = build([r.readings() for r in runs], utc_now(), [str(r.path) for r in runs],
                eta=args.eta, aperture=ap, divergence_deg=divergence)
    print(calfile.save(cal, args.out))
    return 0


def _aperture_from_scan(scan_run, beam_diameter_mm: float):
    """(solid angle, half-angle) from the sample readings of a scan across the beam."""
    import numpy as np

    from calibration import aperture
    from calibration.detector import correct_power, dark_offsets
    from calibration.values import CalibrationError

    r = scan_run.readings()
    sample = r[r["kind"] == "sample"]
    if len(sample) == 0:
        raise CalibrationError(f"{scan_run.path}: no sample readings to scan the beam with")
    power = correct_power(sample["power_w"], sample["range_w"], dark_offsets(r), None)
    distance_mm = float((scan_run.config.get("optics") or {})
                        .get("aperture_distance_mm", 0.0)) or None
    beam_rad = 0.0
    if beam_diameter_mm > 0:
        if distance_mm is None:
            raise CalibrationError("--beam-diameter-mm needs the aperture distance "
                                   "([optics] aperture_distance_mm) in the run's config")
        beam_rad = 0.5 * beam_diameter_mm / distance_mm
    noise = np.std(power[power < 0.02 * power.max()]) if np.any(power < 0.02 * power.max()) else 0
    sigma = np.hypot(noise, 1e-3 * np.abs(power))
    return aperture.from_beam_scan(sample["arm_deg"], power, sigma, beam_radius_rad=beam_rad)


def _use(args: argparse.Namespace) -> int:
    from calibration import calfile
    from gonio.store import META, open_run, write_json_atomic

    run = open_run(args.run)
    meta = dict(run.meta)
    meta["calibration"] = calfile.reference(args.calibration)
    write_json_atomic(run.path / META, meta)
    print(f"{run.path}: calibration {meta['calibration']['file']}")
    return 0
