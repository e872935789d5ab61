"""`gonio reduce RUN`: raw readings -> BSDF values with their uncertainty budget (dark, beam,
aperture, cos o, hemisphere exit; calibration.budget); writes RUN/reduced.csv (the file of
`gonio export --what reduced --format csv`: the run's record and the reduction's facts, u, k,
U = k u, u_NAME per component; calibration.exports.measured) and prints a summary per incidence
and the budget's components.
`gonio reduce RUN --integrals [--integrals-json FILE]`: also the integrated quantities
(reflectance, transmittance, ISO 13696 total scattering, ASTM D1003 haze, ISO 2813 gloss) with
their uncertainty, the fitted model filling what the data do not cover (calibration.integrals).
`gonio reduce --import FILE --out CSV`: a measured file gonio did not make (ASTM E1392, Zemax
tabular BSDF, BiRD universal BRDF, gonio's reduced CSV or NetCDF, a plain CSV;
calibration.imports) as gonio's reduced CSV (calibration.exports.measured)."""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import numpy as np

from calibration.budget import COVERAGE_K
from calibration.signature import DEFAULT_SHARE
from gonio.errors import GonioError
from gonio_cli.incomplete import add_force_option


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
    add_angle_option(p)
    p.add_argument("--signature-share", type=float, default=DEFAULT_SHARE, metavar="FRACTION",
                   help="flag points whose signature exceeds this share of the net signal "
                        f"(default {DEFAULT_SHARE:g})")
    p.add_argument("--coverage-k", type=float, default=COVERAGE_K, metavar="K",
                   help=f"coverage factor of the expanded uncertainty U = k u (default "
                        f"{COVERAGE_K:g}: about 95 %% for a normal distribution)")
    p.add_argument("--integrals", action="store_true",
                   help="also print the integrated quantities with u and U: reflectance, "
                        "transmittance, total scattering (ISO 13696), haze (ASTM D1003), "
                        "gloss (ISO 2813), from the data and a fit over every incidence "
                        "filling what they do not cover (docs/fitting.md)")
    p.add_argument("--integrals-json", metavar="FILE",
                   help="write the integrated quantities as JSON to FILE (implies --integrals)")
    p.set_defaults(func=run, check_args=check_args, reads_run="run")


def add_run_or_import(p: argparse.ArgumentParser) -> None:
    """The run directory (and --force), or --import FILE and the assumption a file without
    uncertainties needs."""
    p.add_argument("run", nargs="?", help="run directory (or --import FILE)")
    add_force_option(p)
    p.add_argument("--import", dest="import_file", metavar="FILE",
                   help="a measured file instead of a run: ASTM E1392 (.astm), Zemax tabular "
                        "BSDF (.bsdf), BiRD universal BRDF (.json), gonio's reduced CSV or "
                        "NetCDF (.nc), or a plain CSV with "
                        "columns theta_i_deg, phi_i_deg, theta_o_deg, phi_o_deg (theta_o above "
                        "90 for transmission), bsdf, optional sigma, wavelength_nm")
    p.add_argument("--sigma-relative", type=float, metavar="FRACTION",
                   help="for an imported file without uncertainties: assume u = FRACTION * "
                        "|bsdf| (stated in the output)")
    p.add_argument("--incidence-deg", type=float, metavar="DEG",
                   help="for an imported CSV table of one incidence (columns theta_o_deg"
                        "[, phi_o_deg], value[, sigma]; without phi_o, theta_o is signed, "
                        "positive on the specular side): its theta_i, unless a header line "
                        "`# theta_i_deg: DEG` gives it")


def imported(args: argparse.Namespace):  # -> calibration.reduced.ReducedData | None
    """The --import file's ReducedData (None without --import); one error for both a run and
    --import, or neither."""
    if (args.run is None) == (args.import_file is None):
        raise GonioError("give a run directory or --import FILE (one of them)")
    if args.import_file is None:
        return None
    from calibration.imports import ImportOptions, read_measured

    return read_measured(args.import_file, ImportOptions(args.eta, args.sigma_relative,
                                                         args.incidence_deg))


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


def add_angle_option(p: argparse.ArgumentParser) -> None:
    """--no-angle-terms, of the verbs that reduce a run with its budget's angle terms."""
    p.add_argument("--no-angle-terms", action="store_true",
                   help="reduce without the budget's angle terms (the stages' repeatability "
                        "and the calibration's angle offsets through the fitted model's slope) "
                        "where they cannot be estimated; every output says U excludes them")


def say_angle_terms(args: argparse.Namespace) -> None:
    """The stderr line of a run reduced with --no-angle-terms."""
    if getattr(args, "no_angle_terms", False) and getattr(args, "run", None) is not None:
        print(f"gonio {args.command}: U excludes the budget's angle terms (--no-angle-terms)",
              file=sys.stderr)


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
    """Lines per component of calibration.budget.summary: own or shared, its median and largest
    share u_c / u over the valid points, its median u_c / f; then k and the median U / f, where
    each type-B figure comes from, and the budget's notes."""
    from calibration.budget import summary as budget_of

    budget = budget_of(data)
    lines = [f"{'component':<20} {'kind':<7} {'median u_c/u':>12} {'max u_c/u':>10} "
             f"{'median u_c/f':>12}"]
    lines += [f"{name:<20} {c['kind'] or '-':<7} {c['median_share']:12.3g} {c['max_share']:10.3g} "
              f"{c['median_relative']:12.3g}"
              for name, c in budget["components"].items() if budget["points"]]
    if budget["points"]:
        lines.append(f"u combined; k = {budget['coverage_k']:g}, U = k u: median U/f "
                     f"{budget['median_expanded_relative']:.3g}")
    lines += [f"source of {name}: {c['source']}"
              for name, c in budget["components"].items() if c["source"]]
    return lines + [f"budget: {note}" for note in budget["notes"]]


def print_integrals(args: argparse.Namespace, data) -> None:
    """With --integrals or --integrals-json: fit over every incidence, print the integrals'
    table (calibration.integrals) and write the JSON file if asked."""
    if not (args.integrals or args.integrals_json):
        return
    import json

    from calibration.fit import fit
    from calibration.integrals import ASSUMPTIONS, integrals, table, to_json
    from calibration.pipeline import DEFAULT_SLOPE_FIT, slope_fit_options

    result = fit(data, slope_fit_options(DEFAULT_SLOPE_FIT))
    found = integrals(data, result)
    k = float(data.meta.get("coverage_k", args.coverage_k))
    print(f"integrals (fill: {result.distribution} fit over every incidence, chi2/dof "
          f"{result.chi2_dof_fit:.3g}; k = {k:g}):")
    print("\n".join(table(found, k)))
    print("\n".join(f"assumed: {a}" for a in ASSUMPTIONS))
    if args.integrals_json:
        path = Path(args.integrals_json)
        path.write_text(json.dumps(to_json(found, k, result), indent=1) + "\n")
        print(f"integrals: {path}")


def check_args(args: argparse.Namespace) -> None:
    """The arguments' checks that need no run (--coverage-k, --integrals-json's folder), made
    before the run is read and anything is written."""
    if not (np.isfinite(args.coverage_k) and args.coverage_k > 0):
        raise GonioError(f"--coverage-k must be a finite number > 0, got {args.coverage_k!r}")
    if args.integrals_json:
        path = Path(args.integrals_json)
        folder = path.parent
        if path.is_dir():
            raise GonioError(f"--integrals-json {path}: is a folder (name the JSON file)")
        if not folder.is_dir() or not os.access(folder, os.W_OK):
            raise GonioError(f"--integrals-json {path}: cannot write in {folder} (no such "
                             "folder, or not writable)")


def run(args: argparse.Namespace) -> int:
    """Reduce, write the CSV, print the summary and the CSV's path last."""
    from calibration.exports.measured import write_reduced_csv
    from calibration.pipeline import reduce_run
    from calibration.signature import summary as signature_summary
    from gonio.record import record_lines, run_record
    from gonio.store import open_run

    if args.import_file is not None or args.run is None:
        return _write_imported(args)  # imported(): one error for both a run and --import
    stored = open_run(args.run, force=args.force)
    data = reduce_run(stored, args.calibration, args.shot_noise_w, args.subtract_signature,
                      args.signature_share, angle_terms=not args.no_angle_terms)
    say_angle_terms(args)
    data.meta["coverage_k"] = args.coverage_k
    out = write_reduced_csv(data, Path(args.out) if args.out else Path(args.run) / "reduced.csv",
                            record_lines(run_record(stored)))
    m = data.meta
    eta = f", eta {m['eta']:g}" if m["eta"] is not None else ""
    print(f"run {args.run}: sample {m['sample']['id']}{eta}, aperture "
          f"{m['aperture_half_angle_deg']:.4g} deg ({m['aperture_sr']:.4g} sr, from "
          f"{m['aperture_from']}), beam {m['beam_mean_w']:.4g} W "
          f"(drift rms {m['beam_drift_rms']:.2%})")
    if "reference" in m:
        ref = m["reference"]
        print(f"normalised to the reference {ref['certificate']['id']} (run {ref['run']}): "
              f"solid angle {ref['solid_angle_sr']['value']:.5g} sr, "
              f"{ref['scale']['value']:.5g} times the aperture's")
    print(f"noise: {m['noise_model']}")
    print("\n".join(summary(data)))
    print("\n".join(budget_summary(data)))
    if "signature" in m:
        print("\n".join(signature_summary(m["signature"])))
    print_integrals(args, data)
    print(out)
    return 0


def _write_imported(args: argparse.Namespace) -> int:
    """Write an imported file as gonio's reduced CSV, with the record it carries; print its
    noise model, the summary and the CSV's path last. A missing --out is named in the same
    error as the inputs the file lacks (calibration.imports.MissingInputs)."""
    from calibration.exports.measured import write_reduced_csv
    from calibration.imports import MissingInputs
    from gonio.record import record_lines

    no_out = "give --out CSV (there is no run directory to write into)"
    try:
        data = imported(args)
    except MissingInputs as exc:
        if args.out:
            raise
        raise MissingInputs(exc.path, [*exc.problems, no_out]) from None
    if not args.out:
        raise GonioError(f"reduce --import: {no_out}")
    out = write_reduced_csv(data, Path(args.out), record_lines(data.meta.get("record", {})))
    print(f"imported {args.import_file}: eta {data.meta['eta']:g}, {len(data.bsdf)} points")
    print(f"noise: {data.meta['noise_model']}")
    print("\n".join(summary(data)))
    print_integrals(args, data)
    print(out)
    return 0
