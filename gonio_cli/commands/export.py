"""`gonio export RUN --format FORMAT [--what raw|reduced|model] [--provenance FILE.toml] --out
FILE`: write what a run measured (raw readings; reduced BSDF with its uncertainties) or its
fitted model; calibration.exports."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from calibration.exports import ExportRequest, checked_what, write
from calibration.exports.bird_supplement import SHAPE_KEYS, read_supplement
from calibration.formats import FORMATS, WHATS
from calibration.values import CalibrationError
from gonio.optics import DESCRIPTIVE_KEYS
from gonio_cli.commands.fit import add_fit_options, emulator_sim, options_from
from gonio_cli.commands.reduce import say_angle_terms
from gonio_cli.incomplete import add_force_option

#: The module's docstring with FORMAT spelled out as the names of calibration.formats.
DESCRIPTION = __doc__.replace("--format FORMAT", f"--format {'|'.join(FORMATS)}")


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the `export` verb."""
    p = subparsers.add_parser("export", description=DESCRIPTION,
                              help=f"export a run ({', '.join(FORMATS)})")
    p.add_argument("run", help="run directory")
    p.add_argument("--format", required=True, choices=tuple(FORMATS))
    p.add_argument("--what", choices=WHATS,
                   help="; ".join(f"{fmt.name}: {' or '.join(fmt.whats)} (default "
                                  f"{fmt.default_what})" for fmt in FORMATS.values())
                   + f". {' and '.join(f.name for f in FORMATS.values() if f.raw_fallback)} "
                     "write the raw readings of a run that cannot be reduced")
    p.add_argument("--out", required=True, metavar="FILE",
                   help="output file; zemax and astm write one file per measured side, as Zemax "
                        "reads a BRDF and a BTDF from separate files: the BTDF here (the BRDF "
                        "if only reflection was measured) and the BRDF beside it as "
                        "STEM-BRDF.SUFFIX. Every file written is printed, one per line")
    p.add_argument("--fit", metavar="FIT.json",
                   help="the fit to export (the output of `gonio fit RUN --json`) instead of "
                        "fitting here with the fit options below (zemax, astm --what model, "
                        "mitsuba, abg); a fit of a model family exports where the family has a "
                        "form (abg: an ABg fit; mitsuba: lambert, lambert+microfacet), and as "
                        "zemax and astm tables of its values")
    add_force_option(p, also="; and export a fit whose chi2/dof says it does not describe "
                             "the data (refused otherwise)")
    p.add_argument("--single-scattering", action="store_true",
                   help="mitsuba: write a multiple-scattering fit as the single-scattering "
                        "material, which drops the multiple scattering (the share of R + T it "
                        "keeps is printed and noted in the file); without it such a fit is "
                        "written as the gonio_multiscatter plugin, or refused where that cannot "
                        "match the model's R + T within 1 %%")
    p.add_argument("--provenance", metavar="FILE.toml",
                   help="bird: what BiRD requires and the run did not record, given now: a "
                        "TOML file with the tables the config and plan take, [provenance], "
                        f"[environment], [optics] (only {', '.join(DESCRIPTIVE_KEYS)}) and "
                        f"[sample] (only {', '.join(SHAPE_KEYS)}). It fills only what the run "
                        "lacks and is refused where it contradicts what the run recorded; the "
                        "BiRD file names it (path and sha256) and the keys it gave")
    add_fit_options(p)
    p.set_defaults(func=run, check_args=check_args, reads_run="run")


def check_args(args: argparse.Namespace) -> None:
    """The arguments' checks that need no run (format, --what, --out's suffix), made before
    the run is read."""
    checked_what(args.format, args.what, Path(args.out))
    if args.provenance is not None and args.format != "bird":
        raise CalibrationError(f"export: --provenance gives what a BiRD file needs; --format "
                               f"{args.format} does not take it")


def run(args: argparse.Namespace) -> int:
    """Write the file(s), print each path and any note (on stderr)."""
    sim = emulator_sim(args.run) if args.diffraction else None
    supplement = None if args.provenance is None else read_supplement(args.provenance)
    request = ExportRequest(args.what, options_from(args, sim), args.fit, args.force,
                            args.calibration, args.shot_noise_w, args.subtract_signature,
                            not args.no_angle_terms, args.single_scattering, supplement)
    paths, notes = write(args.run, args.format, Path(args.out), request)
    if request.what != "raw":
        say_angle_terms(args)
    for note in notes:
        print(note, file=sys.stderr)
    for path in paths:
        print(path)
    return 0
