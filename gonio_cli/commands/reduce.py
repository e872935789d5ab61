"""`gonio reduce RUN`: raw readings -> BSDF values with their uncertainty budget (dark, beam,
aperture, cos o, hemisphere exit; calibration.budget); writes RUN/reduced.csv (u, k, U = k u)
and prints a summary per incidence and the budget's components.
`gonio reduce --import FILE --out CSV`: a measured file gonio did not make (ASTM E1392, Zemax
tabular BSDF, gonio's reduced CSV or NetCDF, a plain CSV; calibration.imports) as gonio's
reduced CSV (calibration.exports.measured)."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from calibration.budget import COVERAGE_K, expanded
from calibration.signature import DEFAULT_SHARE
from gonio.errors import GonioError

CSV_HEADER = ("theta_i_deg,phi_i_deg,theta_o_deg,phi_o_deg,side,bsdf_per_sr,sigma_per_sr,"
              "coverage_k,expanded_per_sr,valid,flags")


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the `reduce` verb."""
    p = subparsers.add_parser("reduce", help="raw readings -> BSDF with uncertainties",
                              description=__doc__)
    add_run_or_import(p)
    p.add_argument("--out", metavar="CSV", help="output file (default RUN/reduced.csv; "
                                                "required with --import)")
    p.add_argument("--eta", type=float, help="the sample's index, for an imported file that "
                                             "does not give it")
    add_reduce_options(p)
    p.add_argument("--signature-share", type=float, default=DEFAULT_SHARE, metavar="FRACTION",
                   help="flag points whose signature exceeds this share of the net signal "
                        f"(default {DEFAULT_SHARE:g})")
    p.add_argument("--coverage-k", type=float, default=COVERAGE_K, metavar="K",
                   help=f"coverage factor of the expanded uncertainty U = k u (default "
                        f"{COVERAGE_K:g}: about 95 %% for a normal distribution)")
    p.set_defaults(func=run)


def add_run_or_import(p: argparse.ArgumentParser) -> None:
    """The run directory, or --import FILE and the assumption a file without uncertainties
    needs."""
    p.add_argument("run", nargs="?", help="run directory (or --import FILE)")
    p.add_argument("--import", dest="import_file", metavar="FILE",
                   help="a measured file instead of a run: ASTM E1392 (.astm), Zemax tabular "
                        "BSDF (.bsdf), gonio's reduced CSV or NetCDF (.nc), or a plain CSV with "
                        "columns theta_i_deg, phi_i_deg, theta_o_deg, phi_o_deg (theta_o above "
                        "90 for transmission), bsdf, optional sigma, wavelength_nm")
    p.add_argument("--sigma-relative", type=float, metavar="FRACTION",
                   help="for an imported file without uncertainties: assume u = FRACTION * "
                        "|bsdf| (stated in the output)")


def imported(args: argparse.Namespace):  # -> calibration.reduced.ReducedData | None
    """The --import file's ReducedData (None without --import); one error for both a run and
    --import, or neither."""
    if (args.run is None) == (args.import_file is None):
        from gonio.errors import GonioError

        raise GonioError("give a run directory or --import FILE (one of them)")
    if args.import_file is None:
        return None
    from calibration.imports import ImportOptions, read_measured

    return read_measured(args.import_file, ImportOptions(args.eta, args.sigma_relative))


def add_reduce_options(p: argparse.ArgumentParser) -> None:
    """The reduction options `reduce`, `fit` and `plot` share."""
    p.add_argument("--calibration", metavar="FILE",
                   help="calibration file to apply (default: the one the run records)")
    p.add_argument("--shot-noise-w", type=float, metavar="W",
                   help="the detector's shot-noise variance of one sample per watt of signal, "
                        "W (2 q B / R); default: the config's [detector] shot_noise_w, else the "
                        "emulated meter's for an all-emulated run, else not modelled")
    p.add_argument("--subtract-signature", action="store_true",
                   help="subtract the bench's own scatter, which the run's signature readings "
                        "measured, with its uncertainty (default: flag the points it biases "
                        "and leave them out)")


def spherical_deg(w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(theta from +z, phi = atan2(y, x)) of unit vectors, degrees."""
    return (np.degrees(np.arctan2(np.hypot(w[:, 0], w[:, 1]), w[:, 2])),
            np.degrees(np.arctan2(w[:, 1], w[:, 0])))


def write_csv(data, path: Path) -> Path:
    """One row per sample reading, in the sample frame, degrees; valid 1/0; flags separated by
    ';' (e.g. signature); sigma is the standard uncertainty u, expanded U = k u."""
    ti, pi = spherical_deg(data.wi)
    to, po = spherical_deg(data.wo)
    side = np.where(data.transmission, "transmission", "reflection")
    k, big_u = expanded(data)
    lines = [CSV_HEADER] + [
        f"{a:.6f},{b:.6f},{c:.6f},{d:.6f},{s},{f:.9g},{e:.3g},{k:g},{x:.3g},{int(v)},"
        f"{g.replace(',', ';')}"
        for a, b, c, d, s, f, e, v, g, x in zip(ti, pi, to, po, side, data.bsdf, data.sigma,
                                                data.valid, data.flags, big_u, strict=True)]
    path.write_text("\n".join(lines) + "\n")
    return path


def summary(data) -> list[str]:
    """Lines per (incidence, side): points, valid points, peak BSDF, median relative sigma."""
    lines = [f"{'theta_i':>8} {'side':<12} {'points':>6} {'valid':>6} {'peak 1/sr':>11} "
             f"{'median sigma/f':>14}"]
    theta_i = np.round(data.theta_i_deg, 1)
    for ti in sorted(set(theta_i.tolist())):
        for side, t in (("reflection", False), ("transmission", True)):
            sel = (theta_i == ti) & (data.transmission == t)
            if not sel.any():
                continue
            good = sel & data.valid & (data.bsdf != 0)
            peak = f"{data.bsdf[good].max():11.4g}" if good.any() else f"{'-':>11}"
            rel = (f"{np.median(data.sigma[good] / np.abs(data.bsdf[good])):14.3g}"
                   if good.any() else f"{'-':>14}")
            lines.append(f"{ti:8g} {side:<12} {int(sel.sum()):6d} {int(good.sum()):6d} "
                         f"{peak} {rel}")
    return lines


def budget_summary(data) -> list[str]:
    """Lines per component: own or shared, its median and largest share u_c / u over the valid
    points; then k and the median U / f, and the budget's notes."""
    good = data.valid & (data.sigma > 0)
    shared = set(data.meta.get("budget", {}).get("shared", ()))
    lines = [f"{'component':<20} {'kind':<7} {'median u_c/u':>12} {'max u_c/u':>10} "
             f"{'median u_c/f':>12}"]
    for name, u in sorted(data.components.items()):
        share = u[good] / data.sigma[good]
        rel = u[good] / np.abs(data.bsdf[good])
        if not good.any():
            continue
        lines.append(f"{name:<20} {'shared' if name in shared else 'own':<7} "
                     f"{np.median(share):12.3g} {share.max():10.3g} {np.median(rel):12.3g}")
    k, big_u = expanded(data)
    if good.any():
        lines.append(f"u combined; k = {k:g}, U = k u: median U/f "
                     f"{np.median(big_u[good] / np.abs(data.bsdf[good])):.3g}")
    lines += [f"budget: {note}" for note in data.meta.get("budget", {}).get("notes", ())]
    return lines


def run(args: argparse.Namespace) -> int:
    """Reduce, write the CSV, print the summary and the CSV's path last."""
    from calibration.pipeline import reduce_run
    from calibration.signature import summary as signature_summary

    if not (np.isfinite(args.coverage_k) and args.coverage_k > 0):
        raise GonioError(f"--coverage-k must be a finite number > 0, got {args.coverage_k!r}")
    data = imported(args)
    if data is not None:
        return _write_imported(data, args)
    data = reduce_run(args.run, args.calibration, args.shot_noise_w, args.subtract_signature,
                      args.signature_share)
    data.meta["coverage_k"] = args.coverage_k
    out = write_csv(data, Path(args.out) if args.out else Path(args.run) / "reduced.csv")
    m = data.meta
    print(f"run {args.run}: sample {m['sample']['id']}, eta {m['eta']:g}, aperture "
          f"{m['aperture_half_angle_deg']:.4g} deg ({m['aperture_sr']:.4g} sr, from "
          f"{m['aperture_from']}), beam {m['beam_mean_w']:.4g} W "
          f"(drift rms {m['beam_drift_rms']:.2%})")
    print(f"noise: {m['noise_model']}")
    print("\n".join(summary(data)))
    print("\n".join(budget_summary(data)))
    if "signature" in m:
        print("\n".join(signature_summary(m["signature"])))
    print(out)
    return 0


def _write_imported(data, args: argparse.Namespace) -> int:
    """Write an imported file as gonio's reduced CSV; print its noise model, the summary and
    the CSV's path last."""
    from calibration.exports.measured import write_reduced_csv
    from gonio.errors import GonioError

    if not args.out:
        raise GonioError("reduce --import: give --out CSV (there is no run directory to write "
                         "into)")
    out = write_reduced_csv(data, Path(args.out))
    print(f"imported {args.import_file}: eta {data.meta['eta']:g}, {len(data.bsdf)} points")
    print(f"noise: {data.meta['noise_model']}")
    print("\n".join(summary(data)))
    print(out)
    return 0
