"""The fit's orders >= 3 (walked): their own error against the data's noise, before and after.

Walter's ground glass (GGX 0.394) and acid-etched glass (GGX 0.553) are scanned afresh at
normal incidence on the emulated bench (the example plans' normal-incidence grids, `gonio scan
--sim`) and reduced; at those fit points the walked orders >= 3 of the fit's model (the truth
alpha, the fit's walks per incidence) are compared with a reference from REFERENCE_WALKS
walks, in units of each point's data sigma: median and worst over points and SEEDS seeds, for
the sequential shared-path walk (before: lobe.walk_to_targets(keyed=False)) and the keyed,
branch-split walk (after: keyed.keyed_walk_to_targets), with the CPU time of one estimate
(covariance included, as the fit's centre node needs it). The reference's own error is shown.
Run: python bench/ms_model_error.py [--seeds 4] [--reference-walks 2097152]
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
             ("after: keyed, split", True, 1 << 17))
REFERENCE_WALKS = 1 << 21


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


def orders3(walk, wo: np.ndarray, walks: int, keyed: bool, seed: int
            ) -> tuple[np.ndarray, np.ndarray, float]:
    """Orders >= 3 of f (1/sr) at normal incidence towards wo, their standard error, CPU s."""
    start = time.process_time()
    mean, err, _ = walk_to_targets(walk, np.array([0.0, 0.0, 1.0]), wo, walks,
                                   np.random.default_rng(seed), min_order=3, keyed=keyed)
    inverse = 1.0 / np.abs(wo[:, 2])
    return mean * inverse, err * inverse, time.process_time() - start


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--reference-walks", type=int, default=REFERENCE_WALKS)
    args = ap.parse_args()
    print(f"load average {os.getloadavg()[0]:.1f}; reference {args.reference_walks} walks "
          f"(keyed, split); error / data sigma over the normal-incidence fit points x "
          f"{args.seeds} seeds")
    print(f"{'sample':>13} {'estimator':>24} {'walks':>7} {'cpu s':>6} {'median':>7} "
          f"{'worst':>7}")
    with tempfile.TemporaryDirectory() as tmp:
        for name, alpha in SAMPLES:
            data = reduce_run(scan_normal_incidence(name, Path(tmp)))
            rows = np.flatnonzero(data.wi[:, 2] > np.cos(np.radians(0.05)))
            wo, sigma = data.wo[rows], data.sigma[rows]
            walk = RandomWalkBSDF(RoughDielectric(distribution="ggx", alpha=alpha, eta=1.51,
                                                  masking="correlated"), walks=1, guided=False)
            orders3(walk, wo[:2], 64, True, 0)  # compile outside the timings
            orders3(walk, wo[:2], 64, False, 0)
            ref, ref_err, _ = orders3(walk, wo, args.reference_walks, True, 999)
            print(f"{name:>13} {'reference':>24} {args.reference_walks:>7} {'':>6} "
                  f"{np.median(ref_err / sigma):7.2f} {np.max(ref_err / sigma):7.2f}")
            for label, keyed, walks in ESTIMATES:
                dev, cpu = [], []
                for seed in range(args.seeds):
                    value, _, seconds = orders3(walk, wo, walks, keyed, seed)
                    dev.append(np.abs(value - ref) / sigma)
                    cpu.append(seconds)
                dev = np.concatenate(dev)
                print(f"{name:>13} {label:>24} {walks:>7} {np.median(cpu):6.2f} "
                      f"{np.median(dev):7.2f} {np.max(dev):7.2f}")


if __name__ == "__main__":
    main()
