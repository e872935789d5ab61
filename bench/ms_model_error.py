"""The fit's orders >= 3 (walked): their own error against the data's noise, before and after.

Walter's ground glass (GGX 0.394) and acid-etched glass (GGX 0.553) are scanned afresh at
normal incidence on the emulated bench (the example plans' normal-incidence grids, `gonio scan
--sim`) and reduced; at those fit points the walked orders >= 3 of the fit's model (the truth
alpha, so many walks per incidence) are compared with a reference from REFERENCE_WALKS walks,
in units of each point's data sigma: median and worst over points and --seeds seeds, for the
sequential shared-path walk (before: lobe.walk_to_targets(keyed=False)) and the keyed,
branch-split walk (after: keyed.keyed_walk_to_targets). "table s": CPU time of the walks of
one fit table (calibration.fit._OrdersTable: 7 alphas 0.1 apart in log alpha, the covariance
at the centre one). The reference's own standard error is shown in its row.
Run: python bench/ms_model_error.py [--seeds 4] [--reference-walks 8388608]
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from calibration.pipeline import reduce_run  # noqa: E402
from sim.bsdf import RoughDielectric  # noqa: E402
from sim.bsdf.multiple_scattering.lobe import walk_to_targets  # noqa: E402
from sim.bsdf.multiple_scattering.model import RandomWalkBSDF  # noqa: E402

SAMPLES = (("ground-glass", 0.394), ("acid-etched", 0.553))
#: Walks per estimate: the fit's before (FitOptions.ms_walks then) and after.
ESTIMATES = (("before: sequential walk", False, 1 << 15), ("after: keyed, split", True, 1 << 15),
             ("after: keyed, split", True, 1 << 16), ("after: keyed, split", True, 1 << 17))
REFERENCE_WALKS = 1 << 23
#: The fit table's alphas (calibration.fit: MS_TABLE_NODES, MS_TABLE_STEP in log alpha).
TABLE_NODES, TABLE_STEP = 7, 0.1


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


def glass(alpha: float) -> RandomWalkBSDF:
    """The fit's walk for the height-correlated GGX glass of this alpha."""
    return RandomWalkBSDF(RoughDielectric(distribution="ggx", alpha=alpha, eta=1.51,
                                          masking="correlated"), walks=1, guided=False)


def orders3(walk, wo: np.ndarray, walks: int, keyed: bool, seed: int,
            covariance: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Orders >= 3 of f (1/sr) at normal incidence towards wo and their standard error."""
    mean, err, _ = walk_to_targets(walk, np.array([0.0, 0.0, 1.0]), wo, walks,
                                   np.random.default_rng(seed), min_order=3,
                                   covariance=covariance, keyed=keyed)
    inverse = 1.0 / np.abs(wo[:, 2])
    return mean * inverse, err * inverse


def table_seconds(alpha: float, wo: np.ndarray, walks: int, keyed: bool) -> float:
    """CPU seconds of the walks of one fit table about alpha (covariance at the centre)."""
    start = time.process_time()
    for node in range(TABLE_NODES):
        orders3(glass(alpha * np.exp((node - TABLE_NODES // 2) * TABLE_STEP)), wo, walks, keyed,
                0, covariance=node == TABLE_NODES // 2)
    return time.process_time() - start


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--reference-walks", type=int, default=REFERENCE_WALKS)
    args = ap.parse_args()
    print(f"load average {os.getloadavg()[0]:.1f}; reference {args.reference_walks} walks "
          f"(keyed, split); error / data sigma over the normal-incidence fit points x "
          f"{args.seeds} seeds")
    print(f"{'sample':>13} {'estimator':>24} {'walks':>7} {'table s':>7} {'median':>7} "
          f"{'worst':>7}")
    with tempfile.TemporaryDirectory() as tmp:
        for name, alpha in SAMPLES:
            data = reduce_run(scan_normal_incidence(name, Path(tmp)))
            rows = np.flatnonzero(data.wi[:, 2] > np.cos(np.radians(0.05)))
            wo, sigma = data.wo[rows], data.sigma[rows]
            walk = glass(alpha)
            for keyed in (True, False):  # compile outside the timings
                orders3(walk, wo[:2], 64, keyed, 0, covariance=True)
            ref, ref_err = orders3(walk, wo, args.reference_walks, True, 999)
            print(f"{name:>13} {'reference':>24} {args.reference_walks:>7} {'':>7} "
                  f"{np.median(ref_err / sigma):7.2f} {np.max(ref_err / sigma):7.2f}")
            for label, keyed, walks in ESTIMATES:
                dev = np.concatenate([np.abs(orders3(walk, wo, walks, keyed, seed)[0] - ref)
                                      / sigma for seed in range(args.seeds)])
                print(f"{name:>13} {label:>24} {walks:>7} "
                      f"{table_seconds(alpha, wo, walks, keyed):7.2f} "
                      f"{np.median(dev):7.2f} {np.max(dev):7.2f}")


if __name__ == "__main__":
    main()
