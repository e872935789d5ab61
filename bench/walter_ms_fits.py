"""The Walter runs fitted with multiple scattering: alpha, chi2/dof and fit time, before and after.

Walter's ground glass (GGX 0.394) and acid-etched glass (GGX 0.553) are scanned afresh on the
emulated bench (the example plans, `gonio scan --sim --time-scale inf`) twice: with the bench's
multiple-scattering tables at 2^21 walks (what the example instruments had before) and as the
instruments have them now (2^24, plane_store keeps them on disk), then fitted as `gonio fit RUN
--multiple-scattering` does (calibration.pipeline.fit_run). Fits: "now", the fit as it is (the
refit walks its points both ways and walks those above MS_REWALK_SIGMA of their data sigma
again); "no rewalk", the same without walking again (the fit before the rewalk); "forward
only", also every walk forward (lobe.walk_to_targets in place of walk_both_ways, the estimator
before the reverse walk). "alone": chi2/dof of the fitted model against the data sigma without
the model's Monte Carlo error, its orders >= 2 walked at the points with EVAL_WALKS walks per
incidence (both ways, seed 7, the same for every fit); fitted / held-out points; "eval": what
that evaluation's own error adds to the fitted points' figure (mean of (its error / sigma)^2).
Times: the fit's wall and CPU seconds (its walks run on keyed.THREADS threads).
Run: python bench/walter_ms_fits.py
"""

from __future__ import annotations

import dataclasses
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

import calibration.fit.orders as orders_module  # noqa: E402
from calibration.fit import FitOptions  # noqa: E402
from calibration.pipeline import fit_run  # noqa: E402
from model.bsdf.multiple_scattering import lobe  # noqa: E402
from model.bsdf.multiple_scattering.keyed import THREADS  # noqa: E402

SAMPLES = (("ground-glass", 0.394), ("acid-etched", 0.553))
EVAL_WALKS, EVAL_SEED = 1 << 23, 7
BENCH_WALKS_BEFORE = 1 << 21
#: (label, forward only, walk again above MS_REWALK_SIGMA), on the bench of each walk count
FITS = {BENCH_WALKS_BEFORE: (("no rewalk", False, False), ("now", False, True)),
        None: (("forward only", True, False), ("no rewalk", False, False), ("now", False, True))}


def scan(name: str, out: Path, bench_walks: int | None) -> Path:
    """The example plan scanned on the emulated bench into out, its [sim.sample] ms_walks
    replaced by bench_walks unless None; the run directory."""
    instrument = ROOT / "examples" / "instruments" / f"sim-walter-{name}.toml"
    plan = (ROOT / "examples" / "plans" / f"walter-{name}.toml").read_text()
    if bench_walks is not None:
        text = re.sub(r"^ms_walks = \d+", f"ms_walks = {bench_walks}", instrument.read_text(),
                      flags=re.M)
        instrument = out / f"{name}-{bench_walks}.toml"
        instrument.write_text(text)
    plan_path = out / f"{name}-{bench_walks}-plan.toml"
    plan_path.write_text(re.sub(r'^instrument = ".*"', f'instrument = "{instrument}"', plan,
                                flags=re.M))
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    lines = subprocess.run([sys.executable, "-m", "gonio_cli", "scan", str(plan_path), "--sim",
                            "--time-scale", "inf", "--out", str(out), "--no-plot",
                            "--no-progress"], env=env, capture_output=True, text=True,
                           check=True).stdout.strip().splitlines()
    return Path(lines[-1])


def fitted(run: Path, forward_only: bool, rewalk: bool) -> tuple[object, object, float, float]:
    """(reduced data, fit result, wall s, CPU s) of the multiple-scattering fit of run."""
    both_ways, threshold = lobe.walk_both_ways, orders_module.MS_REWALK_SIGMA
    if forward_only:
        lobe.walk_both_ways = lobe.walk_to_targets
    if not rewalk:
        orders_module.MS_REWALK_SIGMA = np.inf
    try:
        wall, cpu = time.perf_counter(), time.process_time()
        data, result = fit_run(run, FitOptions(multiple_scattering=True))
        return data, result, time.perf_counter() - wall, time.process_time() - cpu
    finally:
        lobe.walk_both_ways, orders_module.MS_REWALK_SIGMA = both_ways, threshold


def alone(data, result) -> tuple[float, float, float]:
    """chi2/dof against the data sigma alone, fitted (normal incidence) and held-out points,
    and the mean of (the evaluation's own error / sigma)^2 over the fitted points."""
    model = dataclasses.replace(result, walks=EVAL_WALKS, seed=EVAL_SEED)
    f, err = model.predict_with_error(data.wi, data.wo)
    z2 = ((data.bsdf - f) / data.sigma) ** 2
    normal = data.wi[:, 2] > np.cos(np.radians(0.5))
    fit_rows, held_rows = data.valid & normal, data.valid & ~normal
    return (float(z2[fit_rows].sum() / (fit_rows.sum() - len(result.names))),
            float(z2[held_rows].mean()), float(np.mean((err / data.sigma)[fit_rows] ** 2)))


def main() -> None:
    print(f"load average {os.getloadavg()[0]:.1f}; {THREADS} threads; alone: orders >= 2 at "
          f"the points by {EVAL_WALKS} walks per incidence")
    print(f"{'sample':>13} {'bench walks':>11} {'fit':>13} {'alpha +- sigma (pull)':>30} "
          f"{'chi2 fit':>8} {'held':>6} {'alone fit':>9} {'held':>6} {'eval':>5} {'wall s':>7} "
          f"{'CPU s':>6}")
    with tempfile.TemporaryDirectory() as tmp:
        for name, truth in SAMPLES:
            for bench_walks, fits in FITS.items():
                run = scan(name, Path(tmp), bench_walks)
                shown = bench_walks or int(re.search(r"^ms_walks = (\d+)", (
                    ROOT / "examples" / "instruments" / f"sim-walter-{name}.toml").read_text(),
                    flags=re.M).group(1))
                for label, forward_only, rewalk in fits:
                    data, result, wall, cpu = fitted(run, forward_only, rewalk)
                    value, sigma = result.param("alpha")
                    fit_alone, held_alone, evaluation = alone(data, result)
                    print(f"{name:>13} {shown:>11} {label:>13} {value:.7f} +- {sigma:.1e} "
                          f"({(value - truth) / sigma:+.2f}) {result.chi2_dof_fit:8.2f} "
                          f"{result.chi2_dof_heldout:6.2f} {fit_alone:9.2f} {held_alone:6.2f} "
                          f"{evaluation:5.2f} {wall:7.2f} {cpu:6.2f}", flush=True)


if __name__ == "__main__":
    main()
