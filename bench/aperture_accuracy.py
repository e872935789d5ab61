"""Aperture-integral accuracy against run time per reading, narrow and wide lobes (sim.bench).

For Walter's anti-glare (Beckmann alpha 0.023) and acid-etched (GGX alpha 0.553) glass on the
hemisphere, a 10 mm aperture at 500 mm (0.57 deg half-angle) and a 0.03 deg beam divergence,
each quadrature setting (fixed orders n_beam x n_aperture, and the automatic rule at several
rtol) is compared with a converged reference over the readings of an in-plane scan through the
lobes (theta_i 0, 30, 60, 75; reflection and transmission); the baseline is DESIGN.md's
one-point formula. Prints one table per lobe: max and median relative error, nodes and
milliseconds per reading.  Usage: python bench/aperture_accuracy.py [--quick]
"""

from __future__ import annotations

import math
import sys
import time

import numpy as np

from sim.bench import build_bench

LOBES = {"narrow: beckmann alpha 0.023": ("beckmann", 0.023),
         "wide: ggx alpha 0.553": ("ggx", 0.553)}
SETTINGS = [("one-point (baseline)", (0, 0)), ("fixed 1 x 2", (1, 2)), ("fixed 2 x 4", (2, 4)),
            ("fixed 3 x 8", (3, 8)), ("fixed 4 x 16", (4, 16)), ("auto rtol 1e-2", 1e-2),
            ("auto rtol 1e-3", 1e-3), ("auto rtol 1e-4", 1e-4)]
REFERENCE = (10, 40)


def positions(alpha: float, quick: bool) -> list[dict[str, float]]:
    """Stage positions of an in-plane scan through both lobes at theta_i 0, 30, 60, 75."""
    out = []
    for ti in (0.0, 30.0, 60.0, 75.0):
        refracted = math.degrees(math.asin(math.sin(math.radians(ti)) / 1.51))
        for peak, transmitted in ((ti, False), (refracted, True)):
            span = np.arange(-3.0, 3.01, 0.5 if quick else 0.25) if alpha < 0.1 else \
                np.arange(-80.0, 80.1, 10.0 if quick else 5.0) - peak
            for to in peak + span:
                arm = ti + 180.0 - to if transmitted else ti + to
                if abs(((arm + 180.0) % 360.0) - 180.0) > 6.0 and abs(to) < 89.0:
                    out.append({"sample": ti, "arm": arm})
    return out


def bench_for(distribution: str, alpha: float, setting) -> object:
    aperture = {"diameter_mm": 10.0, "distance_mm": 500.0}
    if isinstance(setting, tuple):
        aperture["order"] = list(setting)
    else:
        aperture["rtol"] = setting
    return build_bench({"sample": {"distribution": distribution, "alpha": alpha},
                        "source": {"divergence_deg": 0.03}, "aperture": aperture})


def evaluate(bench, where: list[dict[str, float]]) -> tuple[np.ndarray, float, float]:
    """(fractions, mean BSDF evaluations per reading, mean ms per reading)."""
    bench.power_w(where[0])  # warm up (imports, compiled kernels)
    before = sum(bench.sample.evaluations.values())
    t0 = time.perf_counter()
    values = np.array([bench.power_w(p) for p in where])
    ms = 1e3 * (time.perf_counter() - t0) / len(where)
    nodes = (sum(bench.sample.evaluations.values()) - before) / len(where)
    return values, nodes, ms


def main(quick: bool) -> None:
    for title, (distribution, alpha) in LOBES.items():
        where = positions(alpha, quick)
        reference, ref_nodes, ref_ms = evaluate(bench_for(distribution, alpha, REFERENCE), where)
        seen = reference > 1e-10 * 1e-3  # readings above 1e-10 of the beam
        print(f"\n{title}: {seen.sum()} readings, reference {REFERENCE[0]} x {REFERENCE[1]} "
              f"({ref_nodes:.0f} evaluations, {ref_ms:.1f} ms per reading)")
        print(f"{'setting':<22} {'max rel err':>11} {'median':>9} {'evals/reading':>14} "
              f"{'ms/reading':>10}")
        for name, setting in SETTINGS:
            values, nodes, ms = evaluate(bench_for(distribution, alpha, setting), where)
            err = np.abs(values[seen] / reference[seen] - 1.0)
            print(f"{name:<22} {err.max():11.2e} {np.median(err):9.2e} {nodes:14.0f} {ms:10.2f}")


if __name__ == "__main__":
    main("--quick" in sys.argv)
