"""`gonio export RUN --format csv|netcdf|bluesky|zemax|mitsuba --out FILE`: write a run's
readings (csv, netcdf: one row per reading; bluesky: event-model documents as JSON lines) or
its fitted model (zemax, mitsuba); calibration.exports."""

from __future__ import annotations

import argparse
from pathlib import Path

from calibration.exports import FORMATS, write


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the `export` verb."""
    p = subparsers.add_parser("export", help="export a run (csv, netcdf, bluesky, zemax, mitsuba)",
                              description=__doc__)
    p.add_argument("run", help="run directory")
    p.add_argument("--format", required=True, choices=FORMATS)
    p.add_argument("--out", required=True, metavar="FILE",
                   help="output file; zemax writes one file per measured side, as Zemax reads "
                        "a BRDF and a BTDF from separate files: the BTDF here (the BRDF if "
                        "only reflection was measured) and the BRDF beside it as "
                        "STEM-BRDF.SUFFIX. Every file written is printed, one per line")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Write the file(s) and print each path."""
    for path in write(args.run, args.format, Path(args.out)):
        print(path)
    return 0
