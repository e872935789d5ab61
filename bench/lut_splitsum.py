"""Split-sum rough glass end to end: error against table size and bake time, beside the
albedo-only baseline, and a picture of split sum against brute force.

At random (N.V, alpha, eta), uniform in N.V and alpha and in log eta over the tables' domain,
the brute-force radiance through gonio's model in model.lut.splitsum's procedural environment
(sky gradient, 1-degree sun disk importance-sampled, checker wall) is the reference (two
independent estimates: their half difference is its noise). Split sum = T * P(d, alpha_b)
with four choices: the albedo-only baseline (alpha_b = alpha, d = ideal refraction), with the
blur table's alpha_b, with the direction table's offset, and with both; T, alpha_b and the
offset come from float16 tables of each size (1024 samples per entry) or directly from the
model at the point ("direct": the split sum's own error, no table). Errors are relative,
over the points whose reference is at least FLOOR. Each row is drawn from SEEDS seeds (of the
tables' bakes, the direct estimates and the prefiltered lobe's samples; the reference is
shared): the median error's median [min, max] over them, the other figures' medians.

    python bench/lut_splitsum.py [--points 100] [--picture docs/img/lut_splitsum.png]
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np
from _seeds import SEEDS, median_range
from scipy.stats import qmc

from model.lut import TableSpec, bake
from model.lut.axes import ETA_MAX
from model.lut.direction import lookup_direction
from model.lut.estimators import estimator_for
from model.lut.splitsum import Environment, brute_force, prefiltered

SIZES = [(8, 8, 4), (16, 16, 8), (32, 32, 16)]
KINDS = ("transmission", "transmission-blur", "transmission-direction")
#: Split-sum variants: (name, uses the blur table, uses the direction table).
VARIANTS = [("albedo only (baseline)", False, False), ("+ blur", True, False),
            ("+ direction", False, True), ("+ blur + direction", True, True)]
#: Reference radiance below which a point's relative error is not counted (sky is >= 0.25).
FLOOR = 0.05
ENV = Environment()


def load() -> str:
    """The 1, 5 and 15 minute load averages."""
    return ", ".join(f"{x:.2f}" for x in os.getloadavg())


def sobol(d: int, n: int, seed: int) -> np.ndarray:
    """n scrambled Sobol points in [0, 1)^d."""
    return qmc.Sobol(d=d, scramble=True, seed=seed).random(n)


def random_points(count: int, seed: int) -> np.ndarray:
    """(count, 3) points: N.V in [0.05, 1], alpha in [0.02, 1], log eta uniform."""
    r = np.random.default_rng(seed).random((count, 3))
    return np.column_stack([0.05 + 0.95 * r[:, 0], 0.02 + 0.98 * r[:, 1],
                            ETA_MAX ** (2.0 * r[:, 2] - 1.0)])


def references(points: np.ndarray, samples: int) -> tuple[np.ndarray, np.ndarray]:
    """Brute force at each point: mean of two independent estimates, and their half difference."""
    runs = [np.array([brute_force(ENV, *p, sobol(3, samples, seed), sobol(2, samples // 4,
                                                                            seed + 1))
                      for p in points]) for seed in (101, 202)]
    return 0.5 * (runs[0] + runs[1]), 0.5 * (runs[0] - runs[1])


def direct_channels(points: np.ndarray, samples: int, seed: int) -> dict[str, np.ndarray]:
    """T, blur_alpha and offset estimated from the model at the points themselves."""
    u, rng = sobol(3, samples, 7 + seed), np.random.default_rng(7 + seed)
    return {kind: estimator_for(TableSpec(kind=kind, shape=(2, 2, 2)))(points, u, rng)[:, 0]
            for kind in KINDS}


def baked(shape: tuple[int, ...], seed: int = 0) -> dict:
    """The three float16 tables of shape, 1024 samples per entry, from one seed."""
    return {kind: bake(TableSpec(kind=kind, shape=shape, samples=1024, dtype="float16",
                                 seed=seed))
            for kind in KINDS}


def looked_up(tables: dict, points: np.ndarray) -> dict[str, np.ndarray]:
    """T, blur_alpha and offset at the points from the tables."""
    return {kind: table.lookup(*points.T)[:, 0] for kind, table in tables.items()}


def split_sum(points: np.ndarray, channels: dict, blur: bool, direction: bool,
              samples: int, seed: int = 0) -> np.ndarray:
    """T * P(d, alpha_b) at each point for one variant, the prefiltered lobe's samples from
    one seed."""
    u, u_sun = sobol(2, samples, 31 + 2 * seed), sobol(2, samples // 4, 32 + 2 * seed)
    alpha_b = channels["transmission-blur"] if blur else points[:, 1]
    offset = channels["transmission-direction"] if direction else np.zeros(len(points))
    d = lookup_direction(points[:, 0], points[:, 2], offset)
    return channels["transmission"] * np.array(
        [prefiltered(ENV, d[k], float(alpha_b[k]), u, u_sun) for k in range(len(points))])


def error_table(points: int, samples: int) -> dict:
    """The error of each variant against table size and bake time over SEEDS seeds; returns
    the largest size's tables (of the last seed)."""
    params = random_points(points, seed=3)
    start = time.perf_counter()
    ref, noise = references(params, samples)
    counted = ref >= FLOOR
    print(f"brute force at {points} points, {samples} lobe + {samples // 4} sun samples x 2: "
          f"{time.perf_counter() - start:.1f} s; its noise (relative RMS) "
          f"{np.sqrt(np.mean((noise[counted] / ref[counted]) ** 2)):.1e}; "
          f"{counted.sum()} points with reference >= {FLOOR} counted")
    print(f"{'tables':>10} {'T s':>6} {'blur s':>6} {'dir s':>6}  {'variant':24s} "
          f"{'median [min, max] over seeds':>28} {'rms':>8} {'max':>8}   (relative error)")
    labels = ["direct"] + ["x".join(map(str, s)) for s in SIZES]
    errors: dict[tuple[str, str], list[tuple[float, float, float]]] = {}
    seconds: dict[str, list[list[float]]] = {label: [] for label in labels}
    for seed in range(SEEDS):
        tables = {shape: baked(shape, seed) for shape in SIZES}
        rows = [("direct", direct_channels(params, samples, seed))]
        rows += [(label, looked_up(t, params)) for label, t in zip(labels[1:], tables.values(),
                                                                     strict=True)]
        for label, t in zip(labels[1:], tables.values(), strict=True):
            seconds[label].append([t[k].bake_seconds for k in KINDS])
        for label, channels in rows:
            for name, blur, direction in VARIANTS:
                approx = split_sum(params, channels, blur, direction, samples, seed)
                rel = np.abs(approx[counted] / ref[counted] - 1.0)
                errors.setdefault((label, name), []).append(
                    (np.median(rel), np.sqrt(np.mean(rel**2)), rel.max()))
    for label in labels:
        times = (" ".join(f"{t:6.2f}" for t in np.median(seconds[label], axis=0))
                 if seconds[label] else f"{'-':>6} {'-':>6} {'-':>6}")
        for name, _, _ in VARIANTS:
            runs = np.array(errors[label, name])
            print(f"{label:>10} {times}  {name:24s} {median_range(runs[:, 0], '.3f'):>28} "
                  f"{np.median(runs[:, 1]):8.3f} {np.median(runs[:, 2]):8.3f}")
    return tables[SIZES[-1]]


def picture(path: str, tables: dict, samples: int) -> None:
    """Radiance against N.V at three roughnesses, both sides of glass: brute force and the
    split sum without and with the 32x32x16 blur and direction tables."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    mu = np.linspace(0.05, 1.0, 32)
    fig, axes = plt.subplots(2, 3, figsize=(13, 7), sharex=True)
    for row, eta in enumerate((1.5, 1 / 1.5)):
        for col, alpha in enumerate((0.1, 0.3, 0.6)):
            params = np.column_stack([mu, np.full_like(mu, alpha), np.full_like(mu, eta)])
            channels = looked_up(tables, params)
            ref = [brute_force(ENV, *p, sobol(3, samples, 101), sobol(2, samples // 4, 102))
                   for p in params]
            ax = axes[row, col]
            ax.semilogy(mu, ref, "k.", label="brute force (MC of f_t x environment)")
            for (name, blur, direction), style in zip(VARIANTS[::3], ("C0--", "C3-"),
                                                      strict=True):
                ax.semilogy(mu, split_sum(params, channels, blur, direction, samples), style,
                            label=f"split sum, {name}")
            ax.set_title(f"eta = {eta:.3g}, alpha = {alpha}")
            ax.set_xlabel("N.V")
    axes[0, 0].set_ylabel("radiance toward the viewer")
    axes[1, 0].set_ylabel("radiance toward the viewer")
    axes[0, 0].legend(fontsize=8)
    fig.suptitle("Rough glass in a sky + 1-degree sun + checker wall: split sum (32x32x16 "
                 "float16 tables) against brute force")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    print(f"picture: {path}")


def main() -> None:
    """Error table, then the picture when asked."""
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--points", type=int, default=100)
    parser.add_argument("--samples", type=int, default=2**13,
                        help="lobe samples per brute-force and prefilter estimate")
    parser.add_argument("--picture", metavar="PNG", help="also draw the comparison picture")
    args = parser.parse_args()
    start = time.perf_counter()
    print(f"load average {load()}")
    tables = error_table(args.points, args.samples)
    if args.picture:
        picture(args.picture, tables, args.samples)
    print(f"load average {load()}; bench {time.perf_counter() - start:.0f} s")


if __name__ == "__main__":
    main()
