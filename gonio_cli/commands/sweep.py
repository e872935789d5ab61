"""`gonio sweep SWEEP`: simulated measurements of the emulated bench over every combination of
settings (sample, source, aperture, alignment, detector) and stage positions, in parallel with
Dask like `gonio lut`; writes an .npz of true powers and meter readings. See docs/lut.md."""

from __future__ import annotations

import argparse
from pathlib import Path

from gonio.errors import GonioError


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the `sweep` verb."""
    p = subparsers.add_parser("sweep", help="sweep simulated measurements over bench settings",
                              description=__doc__)
    p.add_argument("sweep", help="sweep TOML file")
    p.add_argument("--out", required=True, metavar="FILE", help="output .npz")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, metavar="N",
                       help="run on a local Dask cluster of N worker processes")
    where.add_argument("--scheduler", metavar="ADDRESS",
                       help="run on an existing Dask cluster, e.g. tcp://host:8786")
    p.add_argument("--progress", action="store_true", help="show a progress bar on stderr")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Check every setting first, then measure; prints a summary line and the output path."""
    # lazy: gonio reaches sim only inside the commands that hand work to it (architecture.md)
    from model.cluster import dask_client, describe
    from sim.sweep import load_sweep, run_sweep

    if Path(args.out).suffix.lower() != ".npz":
        raise GonioError(f"{args.out}: a sweep is written as .npz (NumPy): give the file that "
                         "extension")
    try:
        sweep = load_sweep(args.sweep)
        with dask_client(args.workers, args.scheduler) as client:
            result = run_sweep(sweep, client=client, progress=args.progress)
        layout = describe(args.workers, args.scheduler)
        path = result.save(args.out, layout)
    except ValueError as exc:
        raise GonioError(str(exc)) from None
    except OSError as exc:
        raise GonioError(f"cannot write {args.out}: {exc.strerror or exc}") from None
    settings = len(sweep.settings())
    print(f"swept {settings} setting(s) x {len(sweep.position_list())} position(s) "
          f"in {result.seconds:.2f} s ({layout})")
    print(path)
    return 0
