"""Coverage of the integrals' U = 2u (reduce --integrals) over redrawn noise and shifted grids.

Ground glass (GGX 0.394, n 1.51, the bench's multiple scattering on, tables at 8192 walks) on
the emulated bench, scanned instantly for bench seeds 1..--seeds: reflection and transmission
at theta_i 0 and 60 deg, in plane, theta_o every 10 deg from a start drawn per seed in
[-85, -75) deg (the grid shifted). Each run is reduced, fitted over every incidence (the
default single-scattering fit, which misses the bench's multiple scattering: the model-form
term is exercised) and integrated; the truth is the bench's own BSDF integrated on the same
cells. Per quantity and incidence: the share of runs with |estimate - truth| <= 2u beside the
target 95 %, the rms of (estimate - truth) / u and the median u.
Run: python bench/integral_coverage.py [--seeds 24]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from collections import defaultdict
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "tests" / "fitting")]

from fitting_bench_runs import instrument, plan, scan  # noqa: E402

from calibration.fit import fit  # noqa: E402
from calibration.integrals import (  # noqa: E402
    Integral,
    block_cells,
    incidence,
    integrals,
    value_of,
)
from calibration.pipeline import DEFAULT_SLOPE_FIT, reduce_run, slope_fit_options  # noqa: E402
from sim.truth import EmulatorTruth  # noqa: E402

SAMPLE = {"distribution": "ggx", "alpha": 0.394, "ms_walks": 8192}
INCIDENCES = [0.0, 60.0]
STEP_DEG = 10.0
TARGET = 0.95
K = 2.0


def grids(start_deg: float) -> list[dict]:
    """In-plane reflection and transmission grids from start_deg every STEP_DEG."""
    theta_o = {"start": start_deg, "stop": 85.0, "step": STEP_DEG}
    return [{"side": side, "theta_i_deg": INCIDENCES, "theta_o_deg": theta_o,
             "skip_forbidden": True} for side in ("reflection", "transmission")]


def truth_of(found: Integral, truth: EmulatorTruth, eta: float) -> float:
    """The quantity of the bench's own BSDF on the integral's cells."""
    transmission = found.name in ("transmittance", "tis_forward", "haze")
    grid = block_cells(found.theta_i_deg, transmission, eta)
    f = np.zeros(grid.weight.shape)
    side = grid.on_side
    wi = np.broadcast_to(incidence(found.theta_i_deg), (int(side.sum()), 3))
    f[side] = truth.bench_sample.bsdf(wi, grid.wo[side])
    return value_of(found.name, grid, found.theta_i_deg, f)


def one_run(seed: int, tmp: Path) -> list[tuple[Integral, float]]:
    """(integral, truth) of every quantity of bench seed `seed`'s run."""
    start = -85.0 + STEP_DEG * np.random.default_rng(seed).uniform()
    cfg = instrument(tmp, {"sample": SAMPLE}, seed=seed)
    run = scan(plan(tmp, f"coverage-{seed}", grids(start), dark_every=10, beam_every=10), cfg,
               tmp / "runs")
    data = reduce_run(run)
    found = integrals(data, fit(data, slope_fit_options(DEFAULT_SLOPE_FIT)))
    truth = EmulatorTruth(data.meta["sim"], data.meta["optics"], data.meta["sample"])
    return [(i, truth_of(i, truth, float(data.meta["eta"]))) for i in found]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=24)
    args = ap.parse_args()
    rows: dict[tuple[float, str], list[tuple[float, float]]] = defaultdict(list)
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(1, args.seeds + 1):
            for found, truth in one_run(seed, Path(tmp)):
                rows[(found.theta_i_deg, found.name)].append((found.value - truth, found.u))
    print(f"bench seeds 1-{args.seeds}, grid start shifted per seed; target coverage of "
          f"U = {K:g}u: {TARGET:.0%}")
    print(f"{'theta_i':>7} {'quantity':<14} {'runs':>4} {'coverage':>8} {'rms err/u':>9} "
          f"{'median u':>9} {'median |err|':>12}")
    inside = total = 0
    for (theta_i, name), pairs in sorted(rows.items()):
        err, u = np.array(pairs).T
        covered = np.abs(err) <= K * u
        inside, total = inside + int(covered.sum()), total + len(err)
        print(f"{theta_i:7g} {name:<14} {len(err):4d} {covered.mean():8.1%} "
              f"{np.sqrt(np.mean((err / u) ** 2)):9.2f} {np.median(u):9.2g} "
              f"{np.median(np.abs(err)):12.2g}")
    print(f"all: {inside} of {total} within U = {K:g}u ({inside / total:.1%}; target "
          f"{TARGET:.0%})")


if __name__ == "__main__":
    main()
