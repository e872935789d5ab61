"""`gonio plot RUN [--fit]`: the paper-style figure of a run (measured BSDF per incidence angle,
log scale, with the emulator's truth for an all-emulated run); --fit overlays a fitted model
and its residuals."""

from __future__ import annotations

import argparse
import sys

from gonio_cli.commands.fit import add_fit_options, emulator_sim, fit_warnings, options_from
from gonio_cli.commands.reduce import say_angle_terms
from gonio_cli.incomplete import add_force_option


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the `plot` verb."""
    p = subparsers.add_parser("plot", help="plot a run's reduced BSDF (PNG)", description=__doc__)
    p.add_argument("run", help="run directory")
    p.add_argument("--out", metavar="PNG",
                   help="output file (default RUN/plot.png, RUN/plot-fit.png with --fit)")
    p.add_argument("--fit", action="store_true",
                   help="fit the model (gonio fit's options) and overlay it with residuals")
    add_fit_options(p)
    add_force_option(p)
    p.set_defaults(func=run, reads_run="run")


def run(args: argparse.Namespace) -> int:
    """Reduce, (fit,) plot; print the PNG's path."""
    from calibration.plot import plot_run
    from gonio.store import open_run

    sim = emulator_sim(args.run) if args.fit and args.diffraction else None
    results: list = []
    out = plot_run(open_run(args.run, force=args.force), args.out, fit=args.fit,
                   calibration_file=args.calibration,
                   fit_options=options_from(args, sim) if args.fit else None,
                   shot_noise_w=args.shot_noise_w, subtract_signature=args.subtract_signature,
                   angle_terms=not args.no_angle_terms, fitted=results.append)
    for result in results:  # gonio fit's warnings of the fit drawn, on stderr as it says them
        for line in fit_warnings({**result.to_dict(), "run": args.run}, plotted=True):
            print(f"gonio plot: {line}", file=sys.stderr)
    say_angle_terms(args)
    print(out)
    return 0
