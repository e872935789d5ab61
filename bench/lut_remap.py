"""Issue 18's albedo-table figures in one run: the 32x32x16 transmission table with the old
N.V axis (--remap none) and the remapped one (tir), same Monte Carlo budget (1024 Sobol
points per entry) and the same validation points (uniform in the physical N.V, alpha, eta;
one shared converged reference), with the error near the TIR edge, between the eta nodes
bracketing 1, and elsewhere; the 2-D table at eta = 1.5 (and 1/1.5) against the 3-D table at
other indices; and the quoted focusing approximation against Walter's eq. 17.

    python bench/lut_remap.py [--points 2000] [--entries 1024] [--reference-samples 16384]
"""

from __future__ import annotations

import argparse
import os

import numpy as np

from sim.lut import TableSpec, bake
from sim.lut.bake import grid_points
from sim.lut.focusing import approximation_error
from sim.lut.model import ModelEstimator
from sim.lut.validate import (
    chosen_entries,
    edge_split,
    fixed_index_error,
    max_rms,
    random_points,
    reference,
    stored_values,
    unity_bracket,
)

SHAPE = (32, 32, 16)
OTHER_ETAS = [1.33, 1.45, 1.6, 1.7, 2.0]


def figures(name: str, table, params, ref, entries: int, reference_samples: int,
            band: tuple[float, float]) -> None:
    """One line of entry and lookup errors for a table against the shared reference; the
    eta = 1 part is the band between the old table's eta nodes bracketing 1 (the new table's
    own bracket is much narrower: its eta nodes crowd towards 1)."""
    estimator = ModelEstimator("transmission")
    index = chosen_entries(len(grid_points(table.spec)), entries, seed=2)
    entry_ref, _ = reference(grid_points(table.spec)[index], estimator, reference_samples)
    entry_max, entry_rms = max_rms(stored_values(table)[index] - entry_ref)
    err = table.lookup(*params.T) - ref
    lookup_max, lookup_rms = max_rms(err)
    parts = edge_split(params, err, band)
    print(f"{name:12s} bake {table.bake_seconds:6.1f} s | entries max {entry_max:.4f} rms "
          f"{entry_rms:.4f} | lookups max {lookup_max:.4f} rms {lookup_rms:.4f} | TIR band "
          f"({parts['edge_points']}) max {parts['edge_lookup_max']:.4f} rms "
          f"{parts['edge_lookup_rms']:.4f} | eta in ({parts['unity_eta'][0]:.3f}, "
          f"{parts['unity_eta'][1]:.3f}) ({parts['unity_points']}) max "
          f"{parts['unity_lookup_max']:.4f} rms {parts['unity_lookup_rms']:.4f} | rest max "
          f"{parts['rest_lookup_max']:.4f} rms {parts['rest_lookup_rms']:.4f}")


def main() -> None:
    """Bake, validate and print."""
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--points", type=int, default=2000)
    parser.add_argument("--entries", type=int, default=1024)
    parser.add_argument("--reference-samples", type=int, default=2**14)
    args = parser.parse_args()
    print(f"load average {', '.join(f'{x:.2f}' for x in os.getloadavg())}; "
          f"{'x'.join(map(str, SHAPE))} float16, 1024 samples/entry, {args.points} lookups "
          f"uniform in (N.V, alpha, eta), reference 2 x {args.reference_samples} Sobol points")
    tables = {r: bake(TableSpec(kind="transmission", shape=SHAPE, remap=r))
              for r in ("none", "tir")}
    params = random_points(tables["tir"].spec, args.points, seed=1)
    ref, noise = reference(params, ModelEstimator("transmission"), args.reference_samples)
    print(f"reference noise rms {float(np.sqrt(np.mean(noise**2))):.1e}")
    for name, table in (("before: none", tables["none"]), ("after: tir", tables["tir"])):
        figures(name, table, params, ref, args.entries, args.reference_samples,
                unity_bracket(tables["none"].spec))
    fixed = bake(TableSpec(kind="transmission", shape=SHAPE[:2], eta=1.5))
    print(f"fixed eta 1.5 (and 1/1.5) 32x32 float16: bake {fixed.bake_seconds:.1f} s; against "
          f"the 3-D table at other indices:")
    for row in fixed_index_error(fixed, tables["tir"], OTHER_ETAS + [1 / e for e in OTHER_ETAS]):
        print(f"  eta {row['eta']:.4f} from the eta {row['fixed_eta']:.4f} channel: max "
              f"{row['max']:.4f} rms {row['rms']:.4f}")
    etas = np.exp(np.linspace(np.log(0.4), np.log(2.5), 64))
    for name, part in (("eta < 1", etas[etas < 0.97]), ("eta > 1", etas[etas > 1.03])):
        r = approximation_error(part)
        print(f"focusing, quoted approximation against Walter eq. 17 ({name}, {r['points']} "
              f"facet angles x indices): max relative error {r['max_relative_error']:.3g}, rms "
              f"{r['rms_relative_error']:.3g}, exact / quoted in [{r['exact_over_quoted'][0]:.3g}, "
              f"{r['exact_over_quoted'][1]:.3g}]")


if __name__ == "__main__":
    main()
