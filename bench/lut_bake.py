"""Bake time of the 64x64x32 transmission split-sum table in-process and on a 2-worker local
Dask cluster (the speed-up, with the in-process bake as baseline), then the error-against-
run-time table: max and RMS error of entries and of random lookups for each size and dtype.

    python bench/lut_bake.py [--samples 256] [--skip-accuracy] [--quick]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from sim.lut import Table, TableSpec, bake
from sim.lut.bake import grid_points
from sim.lut.cluster import dask_client
from sim.lut.model import ModelEstimator
from sim.lut.validate import chosen_entries, max_rms, random_points, reference


def bake_times(shape: tuple[int, ...], samples: int) -> None:
    """In-process vs a 2-worker local cluster, same spec; asserts identical bits."""
    spec = TableSpec(kind="transmission", shape=shape, samples=samples)
    local = bake(spec)
    print(f"in-process (threads)   : {local.bake_seconds:8.2f} s   (baseline)")
    start = time.perf_counter()
    with dask_client(workers=2) as client:
        client.run(lambda: __import__("sim.lut.model"))  # workers import the model first
        startup = time.perf_counter() - start
        remote = bake(spec, client=client)
    print(f"2-worker local cluster : {remote.bake_seconds:8.2f} s   "
          f"(+ {startup:.2f} s cluster start)")
    print(f"speed-up               : {local.bake_seconds / remote.bake_seconds:8.2f} x   "
          f"({local.bake_seconds / (remote.bake_seconds + startup):.2f} x with start-up)")
    same = local.data.tobytes() == remote.data.tobytes()
    print(f"identical bits         : {same}")
    if not same:
        raise SystemExit("layouts disagree")


def accuracy_table(kind: str, shapes: list[tuple[int, ...]], samples_list: list[int],
                   dtypes: list[str], entries: int, points: int,
                   reference_samples: int) -> None:
    """Error against bake time; one shared reference at the random points for all sizes."""
    probe = TableSpec(kind=kind, shape=shapes[0])
    estimator = ModelEstimator.for_spec(probe)
    params = random_points(probe, points, seed=1)
    start = time.perf_counter()
    ref_points, noise = reference(params, estimator, reference_samples)
    print(f"reference at {points} random points: {reference_samples} x 2 Sobol points each, "
          f"{time.perf_counter() - start:.1f} s, its noise RMS {np.sqrt(np.mean(noise**2)):.1e}")
    print(f"{'size':>10} {'samples':>7} {'dtype':>7} {'bake s':>7} {'entry max':>10} "
          f"{'entry rms':>10} {'lookup max':>10} {'lookup rms':>10}")
    for shape in shapes:
        for samples in samples_list:
            spec = TableSpec(kind=kind, shape=shape, samples=samples, dtype="float64")
            table = bake(spec, estimator)
            index = chosen_entries(spec, entries, seed=2)
            ref_entries, _ = reference(grid_points(spec)[index], estimator, reference_samples)
            for dtype in dtypes:
                stored = Table(spec=spec, data=table.data.astype(dtype).astype(np.float64))
                flat = stored.data.reshape(-1, len(spec.channels))[index]
                e_max, e_rms = max_rms(flat - ref_entries)
                l_max, l_rms = max_rms(stored.lookup(*params.T) - ref_points)
                print(f"{'x'.join(map(str, shape)):>10} {samples:>7} {dtype:>7} "
                      f"{table.bake_seconds:7.2f} {e_max:10.2e} {e_rms:10.2e} {l_max:10.2e} "
                      f"{l_rms:10.2e}")


def main() -> None:
    """Run both sections."""
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--samples", type=int, default=256, help="Sobol points per entry")
    parser.add_argument("--skip-accuracy", action="store_true")
    parser.add_argument("--quick", action="store_true",
                        help="32x32x16 for the timing, smaller accuracy sweep")
    args = parser.parse_args()
    shape = (32, 32, 16) if args.quick else (64, 64, 32)
    print(f"== bake time, transmission {'x'.join(map(str, shape))}, {args.samples} samples/entry")
    bake_times(shape, args.samples)
    if args.skip_accuracy:
        return
    samples = [64, 256] if args.quick else [64, 256, 1024]
    print("== error against run time, reflection (scale and bias; absolute errors)")
    accuracy_table("reflection", [(16, 16), (32, 32), (64, 64)], samples,
                   ["float16", "float32"], entries=500, points=1000, reference_samples=2**13)
    print("== error against run time, transmission (absolute errors; values up to 1/eta^2)")
    shapes = [(16, 16, 8), (32, 32, 16)] if args.quick else [(16, 16, 8), (32, 32, 16),
                                                              (64, 64, 32)]
    accuracy_table("transmission", shapes, samples, ["float16", "float32"], entries=500,
                   points=1000, reference_samples=2**13)


if __name__ == "__main__":
    main()
