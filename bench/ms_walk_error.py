"""Multiple scattering's Monte Carlo error against walks and run time, median and range over seeds.

For the reference glass (GGX, eta = 1.51) at alpha 0.3 and 1.0, each row drawn from SEEDS (8)
independent seeds and printed as the median with [min, max] over them, the run time as the
median: the eval error against walks per direction pair (RandomWalkBSDF, reference: 2^17 walks
per pair), the white-furnace error against samples (F = 1 conductor, and R + T of the glass),
and the bench's tabulated orders >= 2 (HigherOrderLobe) against walks per table build beside
the per-pair walk (HigherOrders, 1024 walks), against a reference walked at the pairs
themselves. For the tables also the error of the seeds' mean (what does not average out) and
the deterministic part: order 2 interpolated from the grid against order 2 at the pairs.
"""

from __future__ import annotations

import os

import numpy as np
from _seeds import SEEDS, median_range
from multiple_scattering import (
    ALPHAS,
    ETA,
    direction,
    direction_pairs,
    timed,
)

from model.bsdf import RoughDielectric
from model.bsdf.multiple_scattering import (
    HigherOrderLobe,
    Microsurface,
    RandomWalkBSDF,
    albedo_estimate,
    higher_orders_at,
)
from model.bsdf.multiple_scattering.second_order import second_order
from sim.bench.sample import HigherOrders

WALKS = (16, 64, 256, 1024, 4096)  # per direction pair, for the eval error
REFERENCE_WALKS = 1 << 17  # per pair, the eval error's reference
FURNACE_SAMPLES = (1000, 4000, 16000, 64000)
TABLE_WALKS = (1024, 4096, 16384, 65536)  # per HigherOrderLobe build
TABLE_REFERENCE_WALKS = 1 << 18
#: The tables' reference: the mean of two walks at the pairs (TABLE_REFERENCE_WALKS each) from
#: these seeds; their difference states the reference's own error.
TABLE_REFERENCE_SEEDS = (99, 100)
PAIR_WALKS = 1024


def off_grid_pairs() -> tuple[np.ndarray, np.ndarray]:
    """12 pairs between the table's nodes: incidence 0, 32, 60 deg; both lobes, in and out of
    plane (polar angles and azimuths off the 5 x 15 deg grid)."""
    return direction_pairs((0.0, 32.0, 60.0),
                           ((22.0, 172.0), (47.0, 100.0), (152.0, 8.0), (168.0, 172.0)))


def _glass(alpha: float) -> RoughDielectric:
    """The reference glass with the walk's own (height-correlated) masking."""
    return RoughDielectric("ggx", alpha, ETA, masking="correlated")


def _rms_over_peak(value: np.ndarray, ref: np.ndarray) -> float:
    """RMS absolute deviation over the largest reference value (the scale a detector range
    sees)."""
    return float(np.sqrt(np.mean((value - ref) ** 2)) / ref.max())


def _rms_relative(value: np.ndarray, ref: np.ndarray) -> float:
    """RMS relative deviation over the pairs."""
    return float(np.sqrt(np.mean(((value - ref) / ref) ** 2)))


def eval_error_table() -> list[str]:
    """RandomWalkBSDF's eval error over 12 pairs against walks per pair, per seed.

    rms dev: relative RMS deviation from the reference over the pairs; expected: what the
    walks' own standard errors predict for it (the reference's included); rms/peak: RMS
    absolute deviation over the largest reference value; time: one eval of the 12 pairs.
    """
    wi, wo = direction_pairs()
    lines = [f"eval error vs walks per direction pair (GGX glass, eta 1.51, 12 pairs); median "
             f"[min, max] over {SEEDS} seeds, time the median",
             f"{'alpha':>5} {'walks/pair':>10} {'time s':>8} {'rms dev':>26} {'expected':>8} "
             f"{'rms/peak':>29}"]
    for alpha in ALPHAS:
        model_ref = RandomWalkBSDF(_glass(alpha), walks=REFERENCE_WALKS)
        ref, ref_seconds = timed(model_ref.estimate, wi, wo, np.random.default_rng(2016))
        for walks in WALKS:
            model = RandomWalkBSDF(_glass(alpha), walks=walks)
            dev, expected, peak, seconds = [], [], [], []
            for seed in range(SEEDS):
                est, t = timed(model.estimate, wi, wo, np.random.default_rng(seed))
                dev.append(_rms_relative(est.value, ref.value))
                expected.append(np.sqrt(np.mean((est.stderr**2 + ref.stderr**2)
                                                / ref.value**2)))
                peak.append(_rms_over_peak(est.value, ref.value))
                seconds.append(t)
            lines.append(f"{alpha:5.1f} {walks:10d} {np.median(seconds):8.4f} "
                         f"{median_range(dev, '.4f'):>26} {np.median(expected):8.4f} "
                         f"{median_range(peak, '.5f'):>29}")
        lines.append(f"{alpha:5.1f} {REFERENCE_WALKS:10d} {ref_seconds:8.3f} {'(ref)':>26} "
                     f"{np.sqrt(np.mean((ref.stderr / ref.value) ** 2)):8.4f}")
    return lines


def furnace_table() -> list[str]:
    """|albedo - 1| of the F = 1 conductor and of the glass (R + T) against samples, per seed."""
    wi = direction(60.0)
    lines = [f"white furnace at 60 deg incidence: |integral of f cos - 1| vs run time; median "
             f"[min, max] over {SEEDS} seeds, time and std err the median",
             f"{'surface':>10} {'alpha':>5} {'samples':>8} {'time s':>8} {'|E - 1|':>29} "
             f"{'std err':>9}"]
    for kind in ("conductor", "dielectric"):
        for alpha in ALPHAS:
            model = RandomWalkBSDF(Microsurface("ggx", alpha, kind, eta=ETA), walks=1)
            for n in FURNACE_SAMPLES:
                runs = [timed(albedo_estimate, model, wi, np.random.default_rng(seed), n)
                        for seed in range(SEEDS)]
                off = [abs(value - 1.0) for (value, _), _ in runs]
                lines.append(f"{kind:>10} {alpha:5.1f} {n:8d} "
                             f"{np.median([t for _, t in runs]):8.3f} "
                             f"{median_range(off, '.5f'):>29} "
                             f"{np.median([err for (_, err), _ in runs]):9.5f}")
    return lines


def _order2_at_pairs(lobe: HigherOrderLobe, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """Order 2 of f at the pairs themselves (second_order's quadrature, no grid)."""
    return np.array([second_order(lobe.walk.walker, a, b[None])[0] / abs(b[2])
                     for a, b in zip(wi, wo, strict=True)])


def _lobe_row(label: str, runs: list[tuple[np.ndarray, float, float]], ref: np.ndarray) -> str:
    """One row of lobe_table from (values, build s, per pair s) per seed."""
    values = np.array([v for v, _, _ in runs])
    peak = [_rms_over_peak(v, ref) for v in values]
    return (f"{label:>24} {np.median([b for _, b, _ in runs]):8.3f} "
            f"{1e3 * np.median([p for _, _, p in runs]):11.2f} "
            f"{np.median([_rms_relative(v, ref) for v in values]):8.4f} "
            f"{median_range(peak, '.5f'):>29} {_rms_over_peak(values.mean(axis=0), ref):9.5f}")


def lobe_table() -> list[str]:
    """The bench's orders >= 2: HigherOrderLobe (tables per incidence and plane through the
    normal, interpolated) against walks per build, off the grid, beside the per-pair
    HigherOrders (PAIR_WALKS walks per pair) at the same pairs, per seed.

    rms dev: relative RMS deviation from the reference (the mean of higher_orders_at at the
    pairs from TABLE_REFERENCE_SEEDS); rms/peak: RMS absolute deviation over the largest
    reference value; mean of seeds: rms/peak of the seeds' mean values (the part that does not
    average out: interpolation, the reference's own error and what is left of the walks');
    build s: building the tables the 12 pairs need; per pair ms: one more pair once its
    tables exist (what a bench reading then costs).
    """
    wi, wo = off_grid_pairs()
    lines = [f"orders >= 2 for the bench: tables per incidence x plane (GGX glass, eta 1.51, 12 "
             f"off-grid pairs); median [min, max] over {SEEDS} seeds, times the median",
             f"{'alpha':>5} {'method':>24} {'build s':>8} {'per pair ms':>11} {'rms dev':>8} "
             f"{'rms/peak':>29} {'mean of seeds':>13}"]
    for alpha in ALPHAS:
        glass = _glass(alpha)
        refs = [higher_orders_at(glass, wi, wo, TABLE_REFERENCE_WALKS, seed=s,
                                 covariance=False)[0] for s in TABLE_REFERENCE_SEEDS]
        ref = np.mean(refs, axis=0)
        lines.append(f"{alpha:5.1f} reference: mean of {len(refs)} x {TABLE_REFERENCE_WALKS} "
                     f"walks at the pairs, its own error (half their RMS difference) / peak "
                     f"{_rms_over_peak(refs[0], refs[1]) / 2:.5f}")
        runs = []
        for seed in range(SEEDS):
            pair = HigherOrders(glass, PAIR_WALKS, seed=seed, fixed_seed=True)
            value, seconds = timed(pair.eval, wi, wo)
            runs.append((value, 0.0, seconds / len(wi)))
        lines.append(f"{alpha:5.1f} {_lobe_row(f'per-pair walk, {PAIR_WALKS}', runs, ref)}")
        for walks in TABLE_WALKS:
            runs = []
            for seed in range(SEEDS):
                lobe = HigherOrderLobe(glass, walks=walks, seed=seed)
                value, build = timed(lobe.eval, wi, wo)
                _, again = timed(lobe.eval, wi[:1], wo[:1])
                runs.append((value, build, again))
            lines.append(f"{alpha:5.1f} {_lobe_row(f'table, {walks}/build', runs, ref)}")
        exact = _order2_at_pairs(lobe, wi, wo)
        table = lobe.parts(wi, wo)[0]
        lines.append(f"{alpha:5.1f} order 2 from the grid against order 2 at the pairs "
                     f"(deterministic, any walks): rms/peak "
                     f"{np.sqrt(np.mean((table - exact) ** 2)) / ref.max():.5f}, "
                     f"largest {np.max(np.abs(table - exact)) / ref.max():.5f}")
    return lines


def load() -> str:
    """The load average, to read the times by (the machine has 2 shared cores)."""
    return "load average {:.2f} {:.2f} {:.2f} (1, 5, 15 min)".format(*os.getloadavg())


def main() -> None:
    """Print the tables."""
    print(load())
    for table in (eval_error_table, furnace_table, lobe_table):
        print("\n".join(table()))
        print()
    print(load())


if __name__ == "__main__":
    main()
