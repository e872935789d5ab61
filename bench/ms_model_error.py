"""The fit's orders >= 3 (walked): their own error against the data's noise, before and after.

Walter's ground glass (GGX 0.394) and acid-etched glass (GGX 0.553) are scanned afresh at
normal incidence on the emulated bench (the example plans' normal-incidence grids, `gonio scan
--sim`) and reduced; at those fit points the walked orders >= 3 of the fit's model (the truth
alpha, so many walks per incidence) are compared with a reference from REFERENCE_WALKS walks,
in units of each point's data noise (NOISE_COMPONENTS of the reduction's budget: what the run's
own readings measure, not the stated type-B terms, which are shared by the points and dwarf it
on these runs): the median and the worst over the points, each as the median [min, max] over
--seeds seeds (SEEDS), for the
sequential shared-path walk (lobe.walk_to_targets(keyed=False)), the keyed, branch-split
walk (keyed.keyed_walk_to_targets) towards every point, and the fit as it is: the distinct
polar angles walked once (normal incidence: the lobe has no azimuth; lobe.higher_orders_at)
and the term at the fit's result walked MS_CENTRE_WALKS times the table's walks (the refit),
both ways, then, as the fit has it now (calibration.fit.refit_orders), its points whose error
exceeds MS_REWALK_SIGMA of their data sigma (the whole budget, as the fit passes it) walked
again. The scans are reduced as `gonio reduce` does an emulated run (the meter's shot noise
from the emulator's truth).
"walks": those behind the estimate at the truth alpha; "table s": CPU time (and "wall s", on
keyed.THREADS threads) of the walks of one fit (calibration.fit.orders.OrdersTable: 7 alphas 0.1
apart in log alpha, the covariance at the centre one, forward; and the refit's term, both ways
for "both"). The reference's own standard error is shown in its row.
Run: python bench/ms_model_error.py [--seeds 8] [--reference-walks 33554432]
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import NamedTuple

import numpy as np
from _seeds import SEEDS, median_range

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from calibration.fit import MS_CENTRE_WALKS, refit_orders  # noqa: E402
from calibration.pipeline import reduce_run  # noqa: E402
from gonio_cli import emulator_truth  # noqa: E402
from model.bsdf import RoughDielectric  # noqa: E402
from model.bsdf.multiple_scattering.keyed import THREADS  # noqa: E402
from model.bsdf.multiple_scattering.lobe import walk_both_ways, walk_to_targets  # noqa: E402
from model.bsdf.multiple_scattering.model import RandomWalkBSDF  # noqa: E402
from model.bsdf.multiple_scattering.second_order import second_order  # noqa: E402

SAMPLES = (("ground-glass", 0.394), ("acid-etched", 0.553))
#: (label, keyed, FitOptions.ms_walks, walks of the refit at the result / ms_walks (1: no
#: refit), distinct polar angles only): the fit's estimators in the order they were its default.
ESTIMATES = (("sequential walk", False, 1 << 15, 1, False),
             ("keyed, split", True, 1 << 17, 1, False),
             ("distinct, refit x16", True, 1 << 17, MS_CENTRE_WALKS, True),
             ("both ways, refit x16", "both", 1 << 17, MS_CENTRE_WALKS, True),
             ("refit x16 + rewalk (now)", "refit", 1 << 17, MS_CENTRE_WALKS, True))
REFERENCE_WALKS = 1 << 25
#: The fit table's alphas (calibration.fit.orders: MS_TABLE_NODES, MS_TABLE_STEP in log alpha).
TABLE_NODES, TABLE_STEP = 7, 0.1
#: The budget's components that make the data's noise: the readings' own noise and what the
#: run's dark and beam readings measure (calibration.reduce), not the stated type-B terms
#: (linearity, range gain, solid angle, angles).
NOISE_COMPONENTS = ("read_noise", "shot_noise", "dark", "beam_normalisation")


def scan_normal_incidence(name: str, out: Path) -> Path:
    """Scan the example plan's normal-incidence grids on the emulated bench; the run dir."""
    text = (ROOT / "examples" / "plans" / f"walter-{name}.toml").read_text()
    text = re.sub(r"theta_i_deg = \[[^\]]*\]", "theta_i_deg = [0.0]", text)
    text = text.replace('"../instruments/', f'"{ROOT / "examples" / "instruments"}/')
    plan = out / f"{name}.toml"
    plan.write_text(text)
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    lines = subprocess.run([sys.executable, "-m", "gonio_cli", "scan", str(plan), "--sim",
                            "--time-scale", "inf", "--out", str(out / "runs"), "--no-plot",
                            "--no-progress"], env=env, capture_output=True, text=True,
                           check=True).stdout.strip().splitlines()
    return Path(lines[-1])


class FitPoints(NamedTuple):
    """One sample's normal-incidence fit points: wo (n, 3), data sigma, data noise and the
    reduced BSDF f (n,) each."""

    name: str
    alpha: float
    wo: np.ndarray
    sigma: np.ndarray
    noise: np.ndarray
    f: np.ndarray


def fit_points(tmp: Path) -> Iterator[FitPoints]:
    """For each of SAMPLES, scanned afresh at normal incidence under tmp, its fit points (the
    truth alpha with them)."""
    for name, alpha in SAMPLES:
        data = reduce_run(scan_normal_incidence(name, tmp))
        rows = np.flatnonzero(data.wi[:, 2] > np.cos(np.radians(0.05)))
        noise = np.sqrt(sum(data.components[c][rows] ** 2 for c in NOISE_COMPONENTS
                            if c in data.components))
        yield FitPoints(name, alpha, data.wo[rows], data.sigma[rows], noise, data.bsdf[rows])


def glass(alpha: float) -> RandomWalkBSDF:
    """The fit's walk for the height-correlated GGX glass of this alpha."""
    return RandomWalkBSDF(RoughDielectric(distribution="ggx", alpha=alpha, eta=1.51,
                                          masking="correlated"), walks=1, guided=False)


def distinct_polar(wo: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(one direction per distinct polar angle of wo (k, 3), each row's index into them): at
    normal incidence the lobe has no azimuth."""
    cos_o, index = np.unique(np.round(wo[:, 2], 12), return_inverse=True)
    return np.stack([np.sqrt(1.0 - cos_o ** 2), 0.0 * cos_o, cos_o], axis=-1), index.reshape(-1)


def orders3(walk, wo: np.ndarray, walks: int, keyed: bool | str, seed: int, distinct: bool,
            covariance: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Orders >= 3 of f (1/sr) at normal incidence towards wo and their standard error; with
    distinct, each polar angle walked once (the lobe has no azimuth at normal incidence)."""
    targets, index = distinct_polar(wo) if distinct else (wo, None)
    rng, normal = np.random.default_rng(seed), np.array([0.0, 0.0, 1.0])
    mean, err, _ = (walk_both_ways(walk, normal, targets, walks, rng, 3, covariance)
                    if keyed == "both" else
                    walk_to_targets(walk, normal, targets, walks, rng, min_order=3,
                                    covariance=covariance, keyed=keyed))
    inverse = 1.0 / np.abs(targets[:, 2])
    mean, err = mean * inverse, err * inverse
    return (mean[index], err[index]) if distinct else (mean, err)


def refitted3(alpha: float, wo: np.ndarray, walks: int, seed: int, sigma: np.ndarray
              ) -> np.ndarray:
    """Orders >= 3 of the fit's refitted term at normal incidence (calibration.fit.refit_orders:
    walked both ways, the points above MS_REWALK_SIGMA of their sigma walked again), 1/sr."""
    normal = np.broadcast_to([0.0, 0.0, 1.0], wo.shape)
    value = refit_orders("ggx", alpha, 1.51, None, normal, wo, walks, seed, sigma)[0]
    return value - second_order(glass(alpha).walker, normal[0], wo) / np.abs(wo[:, 2])


def table_seconds(alpha: float, wo: np.ndarray, walks: int, refit: int, keyed: bool | str,
                  distinct: bool, sigma: np.ndarray) -> tuple[float, float]:
    """(CPU, wall) seconds of one fit's walks about alpha: the table (covariance at the centre)
    and, with refit > 1, the term at alpha with refit x walks (covariance too; keyed "refit":
    the fit's refit_orders)."""
    start, wall = time.process_time(), time.perf_counter()
    for node in range(TABLE_NODES):  # the table walks forward; only the refit both ways
        orders3(glass(alpha * np.exp((node - TABLE_NODES // 2) * TABLE_STEP)), wo, walks,
                keyed is not False, 0, distinct, covariance=node == TABLE_NODES // 2)
    if keyed == "refit":
        refitted3(alpha, wo, walks * refit, 0, sigma)
    elif refit > 1:
        orders3(glass(alpha), wo, walks * refit, keyed, 0, distinct, covariance=True)
    return time.process_time() - start, time.perf_counter() - wall


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=SEEDS)
    ap.add_argument("--reference-walks", type=int, default=REFERENCE_WALKS)
    args = ap.parse_args()
    emulator_truth.install()
    print(f"load average {os.getloadavg()[0]:.1f}; reference {args.reference_walks} walks "
          f"(both ways); error / data noise over the normal-incidence fit points, median and "
          f"worst point per seed, each the median [min, max] over {args.seeds} seeds; "
          f"{THREADS} threads")
    print(f"{'sample':>13} {'estimator':>26} {'walks':>8} {'table s':>7} {'wall s':>7} "
          f"{'median point':>20} {'worst point':>23}")
    with tempfile.TemporaryDirectory() as tmp:
        for name, alpha, wo, sigma, noise, _ in fit_points(Path(tmp)):
            print(f"{name:>13} data sigma / data noise: median {np.median(sigma / noise):.1f}, "
                  f"smallest {np.min(sigma / noise):.1f}")
            walk = glass(alpha)
            for keyed in (True, False, "both"):  # compile outside the timings
                orders3(walk, wo[:2], 64, keyed, 0, False, covariance=True)
            ref, ref_err = orders3(walk, wo, args.reference_walks, "both", 999, True)
            print(f"{name:>13} {'reference':>26} {args.reference_walks:>8} {'':>15} "
                  f"{np.median(ref_err / noise):20.2f} {np.max(ref_err / noise):23.2f}")
            for label, keyed, walks, centre, distinct in ESTIMATES:
                dev = np.array([
                    np.abs((refitted3(alpha, wo, walks * centre, seed, sigma) if keyed == "refit"
                            else orders3(walk, wo, walks * centre, keyed, seed, distinct)[0])
                           - ref) / noise for seed in range(args.seeds)])
                cpu, wall = table_seconds(alpha, wo, walks, centre, keyed, distinct, sigma)
                print(f"{name:>13} {label:>26} {walks * centre:>8} {cpu:7.2f} {wall:7.2f} "
                      f"{median_range(np.median(dev, axis=1), '.2f'):>20} "
                      f"{median_range(np.max(dev, axis=1), '.2f'):>23}")


if __name__ == "__main__":
    main()
