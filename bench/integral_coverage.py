"""Coverage of the integrals' U = 2u (reduce --integrals) over redrawn noise and shifted grids.

Ground glass (GGX 0.394, n 1.51, the bench's multiple scattering on, tables at 8192 walks) on
the emulated bench, scanned instantly for bench seeds 1..--seeds: reflection and transmission
at theta_i 0 and 60 deg, in plane, theta_o every 10 deg from a start drawn per seed in
[-85, -75) deg (the grid shifted). Each seed also draws the bench's type-B errors that the
config states the figures of: the meter's gain on each range (normal, 1-sigma RANGE_GAIN_REL)
and the aperture's diameter (uniform within +-APERTURE_TOLERANCE_MM of the nominal 10 mm), so
that the shared terms of the budget are exercised. Each run is reduced, fitted over every
incidence (the default single-scattering fit, which misses the bench's multiple scattering:
the model-form term is exercised) and integrated; the truth is the bench's own BSDF integrated
on the same cells. Per quantity and incidence: the share of runs with |estimate - truth| <= 2u
beside the target 95 %, the rms and mean of (estimate - truth) / u, the median u and |error|,
and the coverage and rms of the code at commit f5df95b on the same runs (BEFORE).
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
from sim.devices.photodiode import DEFAULT_RANGES_W  # noqa: E402
from sim.truth import EmulatorTruth  # noqa: E402

SAMPLE = {"distribution": "ggx", "alpha": 0.394, "ms_walks": 8192}
INCIDENCES = [0.0, 60.0]
STEP_DEG = 10.0
TARGET = 0.95
K = 2.0
#: The meter's range gains' relative 1-sigma error, as the config states it and the seeds draw it.
RANGE_GAIN_REL = 0.003
#: The aperture's nominal diameter and its +- tolerance, as the config states them; the seeds
#: draw the true diameter uniformly within it.
APERTURE_MM = 10.0
APERTURE_TOLERANCE_MM = 0.02
#: (coverage, rms err/u, mean err/u) by (theta_i, quantity) of the integrals at commit
#: f5df95b (3-deg azimuth cells, the bare model beyond the rows, the whole change when every
#: other node is left out) on the runs of seeds 1-24 with these type-B draws.
BEFORE: dict[tuple[float, str], tuple[float, float, float]] = {
    (0.0, "haze"): (0.958, 0.94, +0.75), (0.0, "reflectance"): (0.875, 1.23, -0.84),
    (0.0, "tis_backward"): (0.875, 1.20, -0.76), (0.0, "tis_forward"): (1.000, 0.49, +0.03),
    (0.0, "transmittance"): (1.000, 0.52, -0.06), (60.0, "gloss"): (1.000, 0.84, -0.59),
    (60.0, "haze"): (1.000, 0.42, +0.29), (60.0, "reflectance"): (1.000, 0.36, -0.29),
    (60.0, "tis_backward"): (1.000, 0.42, -0.38), (60.0, "tis_forward"): (1.000, 0.38, +0.29),
    (60.0, "transmittance"): (1.000, 0.39, +0.30),
}
BEFORE_ALL = "257 of 264 (97.3%)"


def grids(start_deg: float) -> list[dict]:
    """In-plane reflection and transmission grids from start_deg every STEP_DEG."""
    theta_o = {"start": start_deg, "stop": 85.0, "step": STEP_DEG}
    return [{"side": side, "theta_i_deg": INCIDENCES, "theta_o_deg": theta_o,
             "skip_forbidden": True} for side in ("reflection", "transmission")]


def instrument_with_errors(tmp: Path, seed: int) -> Path:
    """The bench's config for `seed`, stating RANGE_GAIN_REL and APERTURE_TOLERANCE_MM, its
    emulated meter's range gains and its aperture's true diameter drawn from them (the
    [sim.aperture] table appended: the file has none)."""
    rng = np.random.default_rng([seed, 2])
    gains = 1.0 + RANGE_GAIN_REL * rng.standard_normal(len(DEFAULT_RANGES_W))
    diameter = APERTURE_MM + APERTURE_TOLERANCE_MM * rng.uniform(-1.0, 1.0)
    path = instrument(tmp, {"sample": SAMPLE, "detector": {"range_gains": gains.tolist()}},
                      detector={"range_gain_rel": RANGE_GAIN_REL}, seed=seed,
                      optics={"aperture_diameter_mm": APERTURE_MM,
                              "aperture_diameter_tolerance_mm": APERTURE_TOLERANCE_MM})
    path.write_text(path.read_text() + f"\n[sim.aperture]\ndiameter_mm = {diameter!r}\n")
    return path


def truth_of(found: Integral, truth: EmulatorTruth, eta: float,
             cache: dict[tuple[float, bool], np.ndarray]) -> float:
    """The quantity of the bench's own BSDF on the integral's cells (the BSDF at each
    incidence and side's cells kept in `cache`)."""
    transmission = found.name in ("transmittance", "tis_forward", "haze")
    grid = block_cells(found.theta_i_deg, transmission, eta)
    key = (found.theta_i_deg, transmission)
    if key not in cache:
        f = np.zeros(grid.weight.shape)
        side = grid.on_side
        wi = np.broadcast_to(incidence(found.theta_i_deg), (int(side.sum()), 3))
        f[side] = truth.bench_sample.bsdf(wi, grid.wo[side])
        cache[key] = f
    return value_of(found.name, grid, found.theta_i_deg, cache[key])


def one_run(seed: int, tmp: Path) -> list[tuple[Integral, float]]:
    """(integral, truth) of every quantity of bench seed `seed`'s run."""
    start = -85.0 + STEP_DEG * np.random.default_rng(seed).uniform()
    run = scan(plan(tmp, f"coverage-{seed}", grids(start), dark_every=10, beam_every=10),
               instrument_with_errors(tmp, seed), tmp / "runs")
    data = reduce_run(run)
    found = integrals(data, fit(data, slope_fit_options(DEFAULT_SLOPE_FIT)))
    truth = EmulatorTruth(data.meta["sim"], data.meta["optics"], data.meta["sample"])
    cache: dict[tuple[float, bool], np.ndarray] = {}
    return [(i, truth_of(i, truth, float(data.meta["eta"]), cache)) for i in found]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=24)
    args = ap.parse_args()
    rows: dict[tuple[float, str], list[tuple[float, float]]] = defaultdict(list)
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(1, args.seeds + 1):
            for found, truth in one_run(seed, Path(tmp)):
                rows[(found.theta_i_deg, found.name)].append((found.value - truth, found.u))
    print(f"bench seeds 1-{args.seeds}, grid start, range gains ({RANGE_GAIN_REL:g} rel) and "
          f"aperture (+-{APERTURE_TOLERANCE_MM:g} mm) drawn per seed; target coverage of "
          f"U = {K:g}u: {TARGET:.0%}")
    print(f"{'theta_i':>7} {'quantity':<14} {'runs':>4} {'coverage':>8} {'rms err/u':>9} "
          f"{'mean err/u':>10} {'median u':>9} {'median |err|':>12} | {'before: coverage':>16} "
          f"{'rms err/u':>9} {'mean err/u':>10}")
    inside = total = 0
    for (theta_i, name), pairs in sorted(rows.items()):
        err, u = np.array(pairs).T
        covered = np.abs(err) <= K * u
        inside, total = inside + int(covered.sum()), total + len(err)
        before = BEFORE.get((theta_i, name))
        was = (f"{before[0]:16.1%} {before[1]:9.2f} {before[2]:+10.2f}" if before
               else f"{'-':>16} {'-':>9} {'-':>10}")
        print(f"{theta_i:7g} {name:<14} {len(err):4d} {covered.mean():8.1%} "
              f"{np.sqrt(np.mean((err / u) ** 2)):9.2f} {np.mean(err / u):+10.2f} "
              f"{np.median(u):9.2g} {np.median(np.abs(err)):12.2g} | {was}")
    print(f"all: {inside} of {total} within U = {K:g}u ({inside / total:.1%}; target "
          f"{TARGET:.0%}); before (f5df95b, seeds 1-24): {BEFORE_ALL}")


if __name__ == "__main__":
    main()
