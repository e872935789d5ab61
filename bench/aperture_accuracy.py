"""Aperture-integral accuracy against run time per reading, narrow and wide lobes (sim.bench).

For Walter's anti-glare (Beckmann alpha 0.023) and acid-etched (GGX alpha 0.553) glass on the
hemisphere, a 10 mm aperture at 500 mm (0.57 deg half-angle) and a 0.03 deg beam divergence,
each quadrature setting (fixed orders n_beam x n_aperture, and the automatic rule at several
rtol) is compared with a converged reference over the readings of an in-plane scan through the
lobes (theta_i 0, 30, 60, 75; reflection and transmission) plus readings whose aperture holds an
edge of the model (the horizon, GGX's vertical-facet edge, the end of the transmitted lobe).
The reference is the rule split along every edge at orders 6 x 44; its own error is its largest
difference from the 4 x 32 rule. The baseline is the one-point formula P = Phi_i f cos Omega_d.
Prints one table per lobe: max relative error (all readings, and those with an edge in the
aperture), median, BSDF evaluations per reading (all, and those with an edge; with multiple
scattering on a node counts twice: single scattering and the tables), milliseconds per reading,
and the load average.
Usage: python bench/aperture_accuracy.py [--quick]
"""

from __future__ import annotations

import math
import os
import sys
import time
from dataclasses import replace

import numpy as np
from _seeds import DETERMINISTIC

from sim.bench import build_bench
from sim.bench.geometry import sample_frame_directions

LOBES = {"narrow: beckmann alpha 0.023": ("beckmann", 0.023),
         "wide: ggx alpha 0.553": ("ggx", 0.553)}
SETTINGS = [("one-point (baseline)", (0, 0)), ("fixed 1 x 2", (1, 2)), ("fixed 2 x 4", (2, 4)),
            ("fixed 3 x 8", (3, 8)), ("fixed 4 x 16", (4, 16)), ("auto rtol 1e-2", 1e-2),
            ("auto rtol 1e-3", 1e-3), ("auto rtol 1e-4", 1e-4)]
REFERENCE, CHECK = (6, 44), (4, 32)
ETA = 1.51
INCIDENCES = (0.0, 30.0, 60.0, 75.0)


def usable(arm: float, to: float) -> bool:
    """Away from the source (the arm's beam clearance) and not past grazing."""
    return abs(((arm + 180.0) % 360.0) - 180.0) > 6.0 and abs(to) < 90.5


def scan_positions(alpha: float, quick: bool) -> list[dict[str, float]]:
    """Stage positions of an in-plane scan through both lobes at each incidence."""
    out = []
    for ti in INCIDENCES:
        refracted = math.degrees(math.asin(math.sin(math.radians(ti)) / ETA))
        for peak, transmitted in ((ti, False), (refracted, True)):
            span = np.arange(-3.0, 3.01, 0.5 if quick else 0.25) if alpha < 0.1 else \
                np.arange(-80.0, 80.1, 10.0 if quick else 5.0) - peak
            for to in peak + span:
                arm = ti + 180.0 - to if transmitted else ti + to
                if usable(arm, to) and abs(to) < 89.0:
                    out.append({"sample": ti, "arm": float(arm)})
    return out


def edge_positions(quick: bool) -> list[dict[str, float]]:
    """In-plane readings with an edge of the model inside the aperture: tau = arm - sample at
    the horizon (+-90), the vertical-facet edge (cos tau = -cos theta_i / eta) and the end of
    the transmitted lobe (cos(tau + theta_i) = -1 / eta), offset by up to 0.4 deg."""
    out = []
    for ti in INCIDENCES:
        vertical = math.degrees(math.acos(-math.cos(math.radians(ti)) / ETA))
        lobe_end = math.degrees(math.acos(-1.0 / ETA))
        for tau in (90.0, -90.0, vertical, -vertical, lobe_end - ti, -lobe_end - ti):
            for offset in (-0.3, 0.0, 0.3) if quick else (-0.4, -0.2, 0.0, 0.2, 0.4):
                arm = ti + tau + offset
                to = ((tau + offset + 180.0) % 360.0) - 180.0
                if usable(arm, to if abs(to) <= 90.0 else 180.0 - abs(to)):
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


def evaluate(bench, where: list[dict[str, float]]) -> tuple[np.ndarray, np.ndarray, float]:
    """(fractions, BSDF evaluations per reading, mean ms per reading)."""
    bench.power_w(where[0])  # warm up (imports, compiled kernels)
    values, nodes = np.empty(len(where)), np.empty(len(where))
    t0 = time.perf_counter()
    for k, p in enumerate(where):
        before = sum(bench.sample.evaluations.values())
        values[k] = bench.power_w(p)
        nodes[k] = sum(bench.sample.evaluations.values()) - before
    ms = 1e3 * (time.perf_counter() - t0) / len(where)
    return values, nodes, ms


def edge_inside(bench, where: list[dict[str, float]]) -> np.ndarray:
    """Which readings have an edge of the model (not a table kink) inside the aperture."""
    out = []
    for p in where:
        wi, wo = sample_frame_directions(p, flipped=bench.sample.flipped)
        edges = replace(bench.sample.edge_circles(wi), table_step_deg=None)
        out.append(edges.distance(wi, wo) < bench.integral.aperture_rad)
    return np.array(out)


def main(quick: bool) -> None:
    print(f"load average {' '.join(f'{x:.2f}' for x in os.getloadavg())} (1, 5, 15 min)")
    print(f"{DETERMINISTIC}; quadrature, the wide lobe's multiple-scattering tables are walked "
          f"once from the bench's fixed seed and serve every setting and the reference")
    for title, (distribution, alpha) in LOBES.items():
        where = scan_positions(alpha, quick) + edge_positions(quick)
        reference, ref_nodes, ref_ms = evaluate(bench_for(distribution, alpha, REFERENCE), where)
        check, _, _ = evaluate(bench_for(distribution, alpha, CHECK), where)
        seen = reference > 1e-10 * 1e-3  # readings above 1e-10 of the beam
        at_edge = edge_inside(bench_for(distribution, alpha, 1e-3), where) & seen
        own = np.abs(check[seen] / reference[seen] - 1.0).max()
        print(f"\n{title}: {seen.sum()} readings ({at_edge.sum()} with an edge in the "
              f"aperture); reference {REFERENCE[0]} x {REFERENCE[1]} split along the edges "
              f"({ref_nodes.mean():.0f} evaluations, {ref_ms:.1f} ms per reading), its own error "
              f"(max |{CHECK[0]} x {CHECK[1]} / reference - 1|) {own:.1e}")
        print(f"{'setting':<22} {'max rel err':>11} {'at edges':>9} {'median':>9} "
              f"{'evals/reading':>14} {'at edges':>9} {'ms/reading':>10}")
        for name, setting in SETTINGS:
            values, nodes, ms = evaluate(bench_for(distribution, alpha, setting), where)
            err = np.abs(values / np.where(seen, reference, 1.0) - 1.0)
            print(f"{name:<22} {err[seen].max():11.2e} {err[at_edge].max():9.2e} "
                  f"{np.median(err[seen]):9.2e} {nodes.mean():14.0f} "
                  f"{nodes[at_edge].mean():9.0f} {ms:10.2f}")
    print(f"\nload average {' '.join(f'{x:.2f}' for x in os.getloadavg())} (1, 5, 15 min)")


if __name__ == "__main__":
    main("--quick" in sys.argv)
