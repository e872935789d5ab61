"""The Walter round trips' alpha pulls over bench seeds, at the bench's table walks before and now.

The round trip of tests/fitting/test_fitting_emulated_bench.py (ground glass GGX 0.394 and
acid-etched glass GGX 0.553 on the emulated bench: normal incidence fitted, 30 and 60 deg held
out; fit seed = bench seed) for bench seeds 1..--seeds, with the bench's multiple-scattering
tables at --before walks (baseline, in the same run) and at the test's walks now
(test_fitting_emulated_bench.BENCH_MS_WALKS): the pulls (alpha - truth) / sigma, their median
[min, max], mean and spread (standard deviation) over the seeds (SEEDS by default), and the
test's PULL_BIAS and PULL_TOLERANCE. The first run on a machine walks every seed's tables
(about 100 s per seed and sample at 2^24 walks on 2 cores; plane_store keeps them on disk).
Run: python bench/walter_pulls.py [--seeds 8] [--before 2097152]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "tests" / "fitting")]

import test_fitting_emulated_bench as round_trip  # noqa: E402
from _seeds import SEEDS, median_range  # noqa: E402
from fitting_bench_runs import instrument, plan, scan  # noqa: E402

from calibration.fit import FitOptions  # noqa: E402
from calibration.pipeline import fit_run  # noqa: E402

SAMPLES = (("ggx", 0.394), ("ggx", 0.553))


def pull(alpha: float, seed: int, bench_walks: int, tmp: Path) -> float:
    """(alpha - truth) / sigma of the round trip's fit on bench seed `seed`."""
    sample = {**round_trip.sample("ggx", alpha), "ms_walks": bench_walks}
    cfg = instrument(tmp, {"source": round_trip.SOURCE, "sample": sample,
                           "aperture": round_trip.APERTURE}, seed=seed)
    run = scan(plan(tmp, f"pulls-{seed}", round_trip.wide_lobe_grids(), dark_every=8), cfg,
               tmp / "runs")
    _, result = fit_run(run, FitOptions(distributions=("beckmann", "ggx"),
                                        multiple_scattering=True, ms_seed=seed))
    if result.distribution != "ggx":
        raise SystemExit(f"bench seed {seed}, alpha {alpha}: the fit preferred "
                         f"{result.distribution}, so its alpha is not GGX's")
    value, sigma = result.param("alpha")
    return (value - alpha) / sigma


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=SEEDS)
    ap.add_argument("--before", type=int, default=1 << 21)
    args = ap.parse_args()
    print(f"load average {os.getloadavg()[0]:.1f}; bench seeds 1-{args.seeds}, fit seed = "
          f"bench seed; the test's PULL_BIAS and PULL_TOLERANCE as they stand")
    width = 6 * args.seeds
    print(f"{'alpha':>6} {'bench walks':>11} {'pulls':>{width}} {'median [min, max]':>23} "
          f"{'mean':>6} {'spread':>6} {'test bias':>9} {'tolerance':>9}")
    with tempfile.TemporaryDirectory() as tmp:
        for _, alpha in SAMPLES:
            for walks in (args.before, round_trip.BENCH_MS_WALKS):
                pulls = np.array([pull(alpha, seed, walks, Path(tmp))
                                  for seed in range(1, args.seeds + 1)])
                shown = " ".join(f"{p:+.2f}" for p in pulls)
                print(f"{alpha:6.3f} {walks:>11} {shown:>{width}} "
                      f"{median_range(pulls, '+.2f'):>23} {pulls.mean():+6.2f} "
                      f"{pulls.std(ddof=1):6.2f} {round_trip.PULL_BIAS[alpha]:+9.2f} "
                      f"{round_trip.PULL_TOLERANCE[alpha]:9.1f}",
                      flush=True)


if __name__ == "__main__":
    main()
