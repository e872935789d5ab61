"""`gonio lut`: bake a real-time split-sum lookup table from gonio's rough-dielectric model
(transmission: N.V x roughness x eta; reflection: N.V x roughness, F0 scale and bias; and on
the transmission axes the prefilter roughness matching the transmitted lobe, or the lobe's
offset from ideal refraction) into an .npz (or an OpenEXR .exr) with its axes,
parameterisation and model, optionally validated. See docs/lut.md."""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

from gonio.errors import GonioError
from model.bsdf.distributions import WITH_KERNELS
from model.bsdf.masking import MASKINGS

DEFAULT_SIZE = {"transmission": "64x64x32", "reflection": "64x64",
                "transmission-blur": "32x32x16", "transmission-direction": "32x32x16"}


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the `lut` verb."""
    p = subparsers.add_parser("lut", help="bake and validate split-sum lookup tables",
                              description=__doc__)
    p.add_argument("--kind", choices=tuple(DEFAULT_SIZE), required=True,
                   help="transmission (albedo), reflection (F0 scale and bias), "
                        "transmission-blur (prefilter roughness matching the transmitted lobe, "
                        "and its residual), transmission-direction (the lobe's offset from "
                        "ideal refraction); see docs/lut.md")
    p.add_argument("--size", help="nodes per axis, e.g. 64x64x32 (transmission: N.V x "
                   "roughness x eta) or 64x64 (reflection); default per kind as shown")
    p.add_argument("--dtype", choices=("float16", "float32", "float64"), default="float16")
    p.add_argument("--out", required=True, metavar="FILE",
                   help="output .npz, or .exr (OpenEXR, float16 as HALF or float32 as FLOAT, a "
                        "transmission table as an atlas of eta slices; needs gonio[exr])")
    p.add_argument("--samples", type=int, default=1024,
                   help="Sobol points per entry, a power of two (default 1024)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--tile-entries", type=int, default=128,
                   help="entries per tile, the unit of parallel work and of seeding")
    p.add_argument("--distribution", choices=WITH_KERNELS, default="ggx")
    p.add_argument("--masking", choices=MASKINGS, default="correlated")
    p.add_argument("--remap", choices=("tir", "none"),
                   help="N.V coordinate of a transmission table: tir (default) follows the "
                        "critical angle and the Fresnel layer near eta = 1 per (alpha, eta), "
                        "none is t = N.V (tables before it); see docs/lut.md")
    p.add_argument("--eta", type=float, metavar="ETA",
                   help="transmission at this one index: a 2-D N.V x roughness table whose two "
                        "channels are at ETA and 1/ETA (e.g. 1.5: into and out of glass)")
    p.add_argument("--multiple-scattering", action="store_true",
                   help="include multiple scattering (Heitz 2016 random walk; transmission)")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, metavar="N",
                       help="bake on a local Dask cluster of N worker processes sharing the "
                            "cores (cores // N threads each)")
    where.add_argument("--scheduler", metavar="ADDRESS",
                       help="bake on an existing Dask cluster, e.g. tcp://host:8786")
    p.add_argument("--validate", action="store_true",
                   help="check entries and random lookups against converged integrals and "
                        "write the errors into the file")
    p.add_argument("--validate-entries", type=int, default=2048, metavar="K",
                   help="entries checked (a random subset when the table has more)")
    p.add_argument("--validate-points", type=int, default=1000, metavar="P",
                   help="random lookup points checked")
    p.add_argument("--reference-samples", type=int, default=2**14, metavar="S",
                   help="Sobol points of each of the two reference integrals")
    p.add_argument("--progress", action="store_true", help="show a progress bar on stderr")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Bake (and validate) the table and write it; one line per result on stdout."""
    # lazy: model.lut and the cluster helper load only when a table is baked
    from model.cluster import dask_client, describe
    from model.lut import TableSpec, bake, parse_size, validate
    from model.lut.table import check_storable

    try:
        size = args.size or DEFAULT_SIZE[args.kind]
        if args.eta is not None and not args.size:
            size = "x".join(size.split("x")[:2])
        spec = TableSpec(kind=args.kind, shape=parse_size(size),
                         dtype=args.dtype, samples=args.samples, seed=args.seed,
                         tile_entries=args.tile_entries, distribution=args.distribution,
                         masking=args.masking, multiple_scattering=args.multiple_scattering,
                         remap=args.remap, eta=args.eta)
        if args.validate and min(args.validate_entries, args.validate_points) < 1:
            raise ValueError("--validate-entries and --validate-points must be >= 1")
        check_storable(spec, args.out)
        folder = Path(args.out).resolve().parent
        if not folder.is_dir() or not os.access(folder, os.W_OK):
            raise GonioError(f"cannot write {args.out}: {folder} is not a writable folder "
                             "(checked before baking)")
        with dask_client(args.workers, args.scheduler) as client:
            table = bake(spec, client=client, progress=args.progress)
            layout = describe(args.workers, args.scheduler)
            at = f" at eta {spec.eta:g} and {1 / spec.eta:g}" if spec.eta is not None else ""
            print(f"baked {spec.kind}{at} {'x'.join(map(str, spec.shape))} {spec.dtype}, "
                  f"{spec.samples} samples/entry, in {table.bake_seconds:.2f} s ({layout})")
            if args.validate:
                report = validate(table, entries=args.validate_entries,
                                  points=args.validate_points,
                                  reference_samples=args.reference_samples, client=client)
                table.validation = report.to_dict()
                print("validation " + json.dumps(table.validation))
        path = table.save(args.out)
    except ValueError as exc:
        raise GonioError(str(exc)) from None
    except OSError as exc:
        raise GonioError(f"cannot write {args.out}: {exc.strerror or exc}") from None
    print(path)
    return 0
