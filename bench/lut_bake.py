"""Bake time of the 64x64x32 transmission split-sum table, then the error-against-run-time table.

Bake time, all in one run on the same spec: the numpy reference path of model.bsdf (no compiled
kernels: what the bake did before it grouped entries by roughness), then the in-process bake
(Dask threads, one per core, kernels single-threaded in each task: the baseline), a 1-worker
and a 2-worker local Dask cluster (workers x threads = cores), each with its speed-up over
the in-process bake, its cluster start-up time and a check that its bits equal the baseline's.
On a machine whose in-process bake already uses every core a cluster on that same machine
cannot be faster: its speed-up measures what the process boundary costs (serialising tiles
and results, one scheduler), not added compute. A cluster pays off with more machines.

Thread policy, on a smaller table (median of 3 interleaved runs, wall and CPU seconds): the
policy of model.cluster (Dask threads own the cores, kernels one thread per task) against
numba owning the cores (a plain loop over tiles in this thread, kernels on every core) and
against no policy (Dask threads x numba threads, oversubscribed); all must give equal bits.

Accuracy: max and RMS error of entries and of random lookups for each size and dtype; for
transmission, lookups split into points near the total-internal-reflection edge
(eta < 1, |N.V - N.V_c| <= TIR_BAND) and the rest.

Issue 18: the 32x32x16 transmission table at 1024 samples with the old N.V axis
(--remap none) and the remapped one, validated on the same points (uniform in the physical
N.V, alpha, eta) against one reference, split at the TIR band and at the old table's eta
nodes around 1; the 2-D table at eta = 1.5 against the 3-D table at other indices; the quoted
focusing approximation against Walter's eq. 17.

    python bench/lut_bake.py [--samples 256] [--skip-accuracy] [--quick] [--only-issue-18]
                             [--only-accuracy]
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import statistics
import time

import numpy as np
from _seeds import SEEDS, median_range

from model.cluster import dask_client, describe, usable_cores
from model.lut import Table, TableSpec, bake
from model.lut.bake import (
    grid_points,
    integrate_points,
    integrate_tile,
    integrate_tiles,
    tile_arguments,
)
from model.lut.focusing import approximation_error
from model.lut.model import ModelEstimator
from model.lut.validate import (
    TIR_BAND,
    chosen_entries,
    edge_split,
    fixed_index_error,
    max_rms,
    near_critical,
    random_points,
    reference,
    stored_values,
    unity_bracket,
)

#: Width of the layout column of the bake-time lines.
WIDTH = 56


def load() -> str:
    """The 1, 5 and 15 minute load averages."""
    return ", ".join(f"{x:.2f}" for x in os.getloadavg())


def warm_up() -> None:
    """Load the compiled kernels of the bake (from numba's cache) in this process."""
    bake(TableSpec(kind="transmission", shape=(2, 2, 2), samples=64))


def timed_bake(spec: TableSpec, estimator=None, client=None) -> tuple[Table, float]:
    """The baked table and the CPU seconds it took: this process (threads, scheduler, client)
    plus, on a cluster, every worker process."""
    workers_before = client.run(time.process_time) if client is not None else {}
    before = time.process_time()
    table = bake(spec, estimator, client=client)
    cpu = time.process_time() - before
    if client is not None:
        cpu += sum(t - workers_before[w] for w, t in client.run(time.process_time).items())
    return table, cpu


def bake_times(shape: tuple[int, ...], samples: int) -> None:
    """Numpy path, in-process, 1- and 2-worker local clusters; asserts identical bits. The
    table is kept in float64 (the cast to float16 is the same work) so that the bit checks
    and the numpy-vs-kernel difference are not hidden by float16 rounding."""
    spec = TableSpec(kind="transmission", shape=shape, samples=samples, dtype="float64")
    print(f"{usable_cores()} usable cores; load average {load()}")
    warm_up()
    numpy_path, numpy_cpu = timed_bake(
        spec, dataclasses.replace(ModelEstimator.for_spec(spec), backend="numpy"))
    local, cpu = timed_bake(spec)
    base = local.bake_seconds
    label = "numpy reference path (no kernels), in-process"
    difference = np.max(np.abs(numpy_path.data - local.data))
    print(f"{label:{WIDTH}s}: {numpy_path.bake_seconds:7.2f} s ({numpy_cpu:6.2f} CPU s)   "
          f"kernels {numpy_path.bake_seconds / base:.2f}x faster; max |difference| "
          f"{difference:.1e}")
    print(f"{describe(None, None):{WIDTH}s}: {base:7.2f} s ({cpu:6.2f} CPU s)   (baseline)")
    for workers in (1, 2):
        start = time.perf_counter()
        with dask_client(workers=workers) as client:
            client.run(warm_up)
            startup = time.perf_counter() - start
            remote, remote_cpu = timed_bake(spec, client=client)
        same = local.data.tobytes() == remote.data.tobytes()
        print(f"{describe(workers, None):{WIDTH}s}: {remote.bake_seconds:7.2f} s "
              f"({remote_cpu:6.2f} CPU s)   speed-up {base / remote.bake_seconds:.2f}x "
              f"({base / (remote.bake_seconds + startup):.2f}x with its {startup:.2f} s "
              f"start-up); identical bits: {same}")
        if not same:
            raise SystemExit("layouts disagree")
    print(f"load average after: {load()}")


def tiles_of(spec: TableSpec) -> list[tuple]:
    """integrate_tile's arguments for every tile of spec, with the model's estimator."""
    return tile_arguments(grid_points(spec), ModelEstimator.for_spec(spec), samples=spec.samples,
                          seed=spec.seed, tile_entries=spec.tile_entries)


def dask_threads(spec: TableSpec) -> np.ndarray:
    """The table's values as bake integrates them (Dask threads, one per core, kernels one
    thread per task), before bake scales them into the stored table."""
    return integrate_points(grid_points(spec), ModelEstimator.for_spec(spec),
                            samples=spec.samples, seed=spec.seed, tile_entries=spec.tile_entries)


def kernels_own_the_cores(spec: TableSpec) -> np.ndarray:
    """The table's values by a plain loop over tiles: numba's kernels use every core."""
    return integrate_tiles(tiles_of(spec))


def oversubscribed(spec: TableSpec) -> np.ndarray:
    """The values with Dask threads (one per core) each calling the kernels on every core."""
    import dask

    tasks = [dask.delayed(integrate_tile)(*tile) for tile in tiles_of(spec)]
    return np.concatenate(dask.compute(*tasks, scheduler="threads",
                                       num_workers=usable_cores()))


def thread_policy(shape: tuple[int, ...], samples: int, repeats: int = 3) -> None:
    """Median wall and CPU seconds of three ways to spend the cores; asserts equal bits."""
    spec = TableSpec(kind="transmission", shape=shape, samples=samples, dtype="float64")
    ways = {"policy: Dask threads, kernels 1 thread (baseline)": lambda: dask_threads(spec),
            "kernels on every core, one Python thread": lambda: kernels_own_the_cores(spec),
            "Dask threads x kernels on every core": lambda: oversubscribed(spec)}
    times: dict[str, list[tuple[float, float]]] = {name: [] for name in ways}
    values = {}
    for _ in range(repeats):
        for name, way in ways.items():
            wall, cpu = time.perf_counter(), time.process_time()
            values[name] = way()
            times[name].append((time.perf_counter() - wall, time.process_time() - cpu))
    print(f"load average {load()}")
    base = statistics.median(w for w, _ in times[next(iter(ways))])
    for name, runs in times.items():
        wall = statistics.median(w for w, _ in runs)
        cpu = statistics.median(c for _, c in runs)
        same = values[name].tobytes() == values[next(iter(ways))].tobytes()
        print(f"{name:{WIDTH}s}: {wall:7.2f} s ({cpu:6.2f} CPU s)   {base / wall:.2f}x; "
              f"identical bits: {same}")
        if not same:
            raise SystemExit("thread layouts disagree")


def accuracy_table(kind: str, shapes: list[tuple[int, ...]], samples_list: list[int],
                   dtypes: list[str], entries: int, points: int,
                   reference_samples: int) -> None:
    """Error against bake time, each row over SEEDS bakes (seeds 0..SEEDS - 1 of the tables'
    Sobol sets): every figure the median, the RMS errors also [min, max]; one shared reference
    at the random points for all sizes and seeds."""
    probe = TableSpec(kind=kind, shape=shapes[0])
    estimator = ModelEstimator.for_spec(probe)
    params = random_points(probe, points, seed=1)
    transmission = kind == "transmission"
    start = time.perf_counter()
    ref_points, noise = reference(params, estimator, reference_samples)
    print(f"reference at {points} random points: {reference_samples} x 2 Sobol points each, "
          f"{time.perf_counter() - start:.1f} s, its noise RMS {np.sqrt(np.mean(noise**2)):.1e}")
    print(f"each row: {SEEDS} seeds of the bake; median, the RMS errors also [min, max]")
    split = ""
    if transmission:
        print(f"TIR edge: {near_critical(params).sum()} of the {points} points have eta < 1 "
              f"and |N.V - sqrt(1 - eta^2)| <= {TIR_BAND}")
        split = f" {'edge max':>9} {'edge rms':>9} {'rest max':>9} {'rest rms':>9}"
    print(f"{'size':>10} {'samples':>7} {'dtype':>7} {'bake s':>7} {'entry max':>9} "
          f"{'entry rms':>9} {'look max':>9} {'look rms':>9}{split} {'entry rms range':>20} "
          f"{'look rms range':>20}")
    for shape in shapes:
        grid = grid_points(TableSpec(kind=kind, shape=shape))
        index = chosen_entries(len(grid), entries, seed=2)
        ref_entries, _ = reference(grid[index], estimator, reference_samples)
        for samples in samples_list:
            rows: dict[str, list[list[float]]] = {dtype: [] for dtype in dtypes}
            seconds = []
            for seed in range(SEEDS):
                spec = TableSpec(kind=kind, shape=shape, samples=samples, dtype="float64",
                                 seed=seed)
                table = bake(spec, estimator)
                seconds.append(table.bake_seconds)
                for dtype in dtypes:
                    stored = Table(spec=spec, data=table.data.astype(dtype).astype(np.float64))
                    err = stored.lookup(*params.T) - ref_points
                    row = [*max_rms(stored_values(stored)[index] - ref_entries), *max_rms(err)]
                    if transmission:
                        parts = edge_split(params, err)
                        row += [parts[f"{part}_lookup_{stat}"] for part in ("edge", "rest")
                                for stat in ("max", "rms")]
                    rows[dtype].append(row)
            for dtype, runs in rows.items():
                runs = np.array(runs)
                print(f"{'x'.join(map(str, shape)):>10} {samples:>7} {dtype:>7} "
                      f"{np.median(seconds):7.2f} "
                      + " ".join(f"{x:9.2e}" for x in np.median(runs, axis=0))
                      + f" [{runs[:, 1].min():.2e}, {runs[:, 1].max():.2e}]"
                      + f" [{runs[:, 3].min():.2e}, {runs[:, 3].max():.2e}]")


REMAP_SHAPE = (32, 32, 16)
OTHER_ETAS = [1.33, 1.45, 1.6, 1.7, 2.0]


def remap_figures(name: str, tables: list[Table], params: np.ndarray, ref: np.ndarray,
                  entries: int, reference_samples: int, band: tuple[float, float]) -> None:
    """One line of entry and lookup errors for one table spec baked from several seeds,
    against the shared reference: the medians, the lookups' also [min, max]; the eta = 1 part
    is the band between the old table's eta nodes bracketing 1 (the new table's own bracket is
    much narrower: its eta nodes crowd towards 1)."""
    estimator = ModelEstimator("transmission")
    index = chosen_entries(len(grid_points(tables[0].spec)), entries, seed=2)
    entry_ref, _ = reference(grid_points(tables[0].spec)[index], estimator, reference_samples)
    figures = []
    for table in tables:
        err = table.lookup(*params.T) - ref
        parts = edge_split(params, err, band)
        figures.append([*max_rms(stored_values(table)[index] - entry_ref), *max_rms(err),
                        parts["edge_lookup_max"], parts["edge_lookup_rms"],
                        parts["unity_lookup_max"], parts["unity_lookup_rms"],
                        parts["rest_lookup_max"], parts["rest_lookup_rms"]])
    figures = np.array(figures)
    m = np.median(figures, axis=0)
    print(f"{name:12s} bake {np.median([t.bake_seconds for t in tables]):6.1f} s | entries max "
          f"{m[0]:.4f} rms {m[1]:.4f} | lookups max {median_range(figures[:, 2], '.4f')} rms "
          f"{median_range(figures[:, 3], '.4f')} | TIR band ({parts['edge_points']}) max "
          f"{m[4]:.4f} rms {m[5]:.4f} | eta in ({parts['unity_eta'][0]:.3f}, "
          f"{parts['unity_eta'][1]:.3f}) ({parts['unity_points']}) max {m[6]:.4f} rms "
          f"{m[7]:.4f} | rest max {m[8]:.4f} rms {m[9]:.4f}")


def issue_18(points: int = 2000, entries: int = 1024, reference_samples: int = 2**14) -> None:
    """Issue 18's albedo-table figures in one run: the 32x32x16 table with the old N.V axis
    and the remapped one (same budget, SEEDS bakes each, same validation points uniform in the
    physical parameters, one shared reference), the fixed-index table against the 3-D one at
    other indices, and the quoted focusing approximation against Walter's eq. 17."""
    print(f"== issue 18, before (--remap none) and after (tir): load average {load()}; "
          f"{'x'.join(map(str, REMAP_SHAPE))} float16, 1024 samples/entry, {points} lookups "
          f"uniform in (N.V, alpha, eta), reference 2 x {reference_samples} Sobol points; "
          f"{SEEDS} seeds of each bake: medians, lookups also [min, max]")
    tables = {r: [bake(TableSpec(kind="transmission", shape=REMAP_SHAPE, remap=r, seed=seed))
                  for seed in range(SEEDS)] for r in ("none", "tir")}
    params = random_points(tables["tir"][0].spec, points, seed=1)
    ref, noise = reference(params, ModelEstimator("transmission"), reference_samples)
    print(f"reference noise rms {float(np.sqrt(np.mean(noise**2))):.1e}")
    for name, runs in (("before: none", tables["none"]), ("after: tir", tables["tir"])):
        remap_figures(name, runs, params, ref, entries, reference_samples,
                      unity_bracket(tables["none"][0].spec))
    fixed = bake(TableSpec(kind="transmission", shape=REMAP_SHAPE[:2], eta=1.5))
    print(f"fixed eta 1.5 (and 1/1.5) 32x32 float16: bake {fixed.bake_seconds:.1f} s; against "
          f"the 3-D table (seed 0) at other indices:")
    for row in fixed_index_error(fixed, tables["tir"][0],
                                 OTHER_ETAS + [1 / e for e in OTHER_ETAS]):
        print(f"  eta {row['eta']:.4f} from the eta {row['fixed_eta']:.4f} channel: max "
              f"{row['max']:.4f} rms {row['rms']:.4f}")
    etas = np.exp(np.linspace(np.log(0.4), np.log(2.5), 64))
    for name, part in (("eta < 1", etas[etas < 0.97]), ("eta > 1", etas[etas > 1.03])):
        r = approximation_error(part)
        print(f"focusing, quoted approximation against Walter eq. 17 ({name}, {r['points']} "
              f"facet angles x indices): max relative error {r['max_relative_error']:.3g}, rms "
              f"{r['rms_relative_error']:.3g}, exact / quoted in [{r['exact_over_quoted'][0]:.3g}, "
              f"{r['exact_over_quoted'][1]:.3g}]")


def main() -> None:
    """Run the sections."""
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--samples", type=int, default=256, help="Sobol points per entry")
    parser.add_argument("--skip-accuracy", action="store_true")
    parser.add_argument("--quick", action="store_true",
                        help="32x32x16 for the timing, smaller accuracy sweep")
    parser.add_argument("--only-issue-18", action="store_true",
                        help="only the remap before/after, fixed-index and focusing figures")
    parser.add_argument("--only-accuracy", action="store_true",
                        help="only the error-against-run-time tables and issue 18's figures")
    args = parser.parse_args()
    if args.only_issue_18:
        issue_18()
        return
    if not args.only_accuracy:
        shape = (32, 32, 16) if args.quick else (64, 64, 32)
        print(f"== bake time, transmission {'x'.join(map(str, shape))}, {args.samples} "
              f"samples/entry")
        bake_times(shape, args.samples)
        small = (32, 32, 4) if args.quick else (64, 64, 8)
        print(f"== thread policy, transmission {'x'.join(map(str, small))}, {args.samples} "
              f"samples/entry, {usable_cores()} cores")
        thread_policy(small, args.samples)
    if args.skip_accuracy:
        return
    samples = [64, 256] if args.quick else [64, 256, 1024]
    print(f"== error against run time, reflection (scale and bias; absolute errors); "
          f"load average {load()}")
    accuracy_table("reflection", [(16, 16), (32, 32), (64, 64)], samples,
                   ["float16", "float32"], entries=500, points=1000, reference_samples=2**13)
    print(f"== error against run time, transmission (absolute errors; values up to 1/eta^2); "
          f"load average {load()}")
    shapes = [(16, 16, 8), (32, 32, 16)] if args.quick else [(16, 16, 8), (32, 32, 16),
                                                              (64, 64, 32)]
    accuracy_table("transmission", shapes, samples, ["float16", "float32"], entries=500,
                   points=2000, reference_samples=2**13)
    issue_18()
    print(f"load average at the end: {load()}")


if __name__ == "__main__":
    main()
