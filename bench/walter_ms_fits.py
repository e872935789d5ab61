"""The Walter runs fitted with multiple scattering: alpha, chi2/dof and fit time, before and after.

Walter's ground glass (GGX 0.394) and acid-etched glass (GGX 0.553) are scanned afresh on the
emulated bench (the example plans, `gonio scan --sim --time-scale inf`) and fitted as
`gonio fit RUN --multiple-scattering` does (calibration.pipeline.fit_run). "now": the fit as
it is (its refit and held-out points walk the transmitted targets in reverse where a pilot
finds that better, lobe.walk_both_ways). Baseline in the same run, on the same scan: the same
fit with every walk forward (lobe.walk_to_targets in place of walk_both_ways), the estimator
before the reverse walk. "alone": chi2/dof of the fitted model against the data sigma without
the model's Monte Carlo error, its orders >= 2 walked at the points with EVAL_WALKS walks per
incidence (both ways, seed 7, the same for both fits); fitted / held-out points. Times: the
fit's wall and CPU seconds (its walks run on keyed.THREADS threads).
Run: python bench/walter_ms_fits.py
"""

from __future__ import annotations

import dataclasses
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from calibration.fit import FitOptions  # noqa: E402
from calibration.pipeline import fit_run  # noqa: E402
from sim.bsdf.multiple_scattering import lobe  # noqa: E402
from sim.bsdf.multiple_scattering.keyed import THREADS  # noqa: E402

SAMPLES = (("ground-glass", 0.394), ("acid-etched", 0.553))
EVAL_WALKS, EVAL_SEED = 1 << 21, 7


def scan(name: str, out: Path) -> Path:
    """The example plan scanned on the emulated bench into out; the run directory."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    lines = subprocess.run([sys.executable, "-m", "gonio_cli", "scan",
                            str(ROOT / "examples" / "plans" / f"walter-{name}.toml"), "--sim",
                            "--time-scale", "inf", "--out", str(out), "--no-plot",
                            "--no-progress"], env=env, capture_output=True, text=True,
                           check=True).stdout.strip().splitlines()
    return Path(lines[-1])


def fitted(run: Path, forward_only: bool) -> tuple[object, object, float, float]:
    """(reduced data, fit result, wall s, CPU s) of the multiple-scattering fit of run."""
    both_ways = lobe.walk_both_ways
    if forward_only:
        lobe.walk_both_ways = lobe.walk_to_targets
    try:
        wall, cpu = time.perf_counter(), time.process_time()
        data, result = fit_run(run, FitOptions(multiple_scattering=True))
        return data, result, time.perf_counter() - wall, time.process_time() - cpu
    finally:
        lobe.walk_both_ways = both_ways


def alone(data, result) -> tuple[float, float]:
    """chi2/dof against the data sigma alone, fitted (normal incidence) and held-out points."""
    model = dataclasses.replace(result, walks=EVAL_WALKS, seed=EVAL_SEED)
    f = model.predict_with_error(data.wi, data.wo)[0]
    z2 = ((data.bsdf - f) / data.sigma) ** 2
    normal = data.wi[:, 2] > np.cos(np.radians(0.5))
    fit_rows, held_rows = data.valid & normal, data.valid & ~normal
    return (float(z2[fit_rows].sum() / (fit_rows.sum() - len(result.names))),
            float(z2[held_rows].mean()))


def main() -> None:
    print(f"load average {os.getloadavg()[0]:.1f}; {THREADS} threads; alone: orders >= 2 at "
          f"the points by {EVAL_WALKS} walks per incidence")
    print(f"{'sample':>13} {'fit':>13} {'alpha +- sigma (pull)':>30} {'chi2 fit':>8} "
          f"{'held':>6} {'alone fit':>9} {'held':>6} {'wall s':>7} {'CPU s':>6}")
    with tempfile.TemporaryDirectory() as tmp:
        for name, truth in SAMPLES:
            run = scan(name, Path(tmp))
            for label, forward_only in (("forward only", True), ("now", False)):
                data, result, wall, cpu = fitted(run, forward_only)
                value, sigma = result.param("alpha")
                fit_alone, held_alone = alone(data, result)
                print(f"{name:>13} {label:>13} {value:.7f} +- {sigma:.1e} "
                      f"({(value - truth) / sigma:+.2f}) {result.chi2_dof_fit:8.2f} "
                      f"{result.chi2_dof_heldout:6.2f} {fit_alone:9.2f} {held_alone:6.2f} "
                      f"{wall:7.2f} {cpu:6.2f}", flush=True)


if __name__ == "__main__":
    main()
