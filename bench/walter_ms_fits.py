"""The Walter runs fitted with multiple scattering: alpha, chi2/dof and fit time over fit seeds.

Walter's ground glass (GGX 0.394) and acid-etched glass (GGX 0.553) are scanned afresh on the
emulated bench (the example plans, `gonio scan --sim --time-scale inf`) twice: with the bench's
multiple-scattering tables at 2^21 walks (the baseline) and as the example instruments have
them (2^24, plane_store keeps them on disk), then each scan is fitted as `gonio fit RUN
--multiple-scattering` does (calibration.pipeline.fit_run) with the fit's walks drawn from
SEEDS seeds (FitOptions.ms_seed; the scan, one draw of the bench's noise, is shared). Fits:
"now", the fit as it is (the refit walks its points both ways and walks those above
MS_REWALK_SIGMA of their data sigma again); "no rewalk", the same without walking again (the
baseline of the rewalk); "forward only", also every walk forward (lobe.walk_to_targets in place
of walk_both_ways: the baseline of the reverse walk). Each row: alpha and its pull from the
microsurface's alpha, (alpha - truth) / sigma, as the median [min, max] over the seeds; sigma,
chi2/dof on the fitted (normal incidence) and held-out points and the fit's wall and CPU
seconds (its walks run on keyed.THREADS threads) as medians.
Run: python bench/walter_ms_fits.py
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from _seeds import SEEDS, median_range

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import calibration.fit.orders as orders_module  # noqa: E402
from calibration.fit import FitOptions  # noqa: E402
from calibration.pipeline import fit_run  # noqa: E402
from model.bsdf.multiple_scattering import lobe  # noqa: E402
from model.bsdf.multiple_scattering.keyed import THREADS  # noqa: E402

SAMPLES = (("ground-glass", 0.394), ("acid-etched", 0.553))
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


def fitted(run: Path, forward_only: bool, rewalk: bool, seed: int
           ) -> tuple[object, float, float]:
    """(fit result, wall s, CPU s) of the multiple-scattering fit of run, its walks from
    seed."""
    both_ways, threshold = lobe.walk_both_ways, orders_module.MS_REWALK_SIGMA
    if forward_only:
        lobe.walk_both_ways = lobe.walk_to_targets
    if not rewalk:
        orders_module.MS_REWALK_SIGMA = np.inf
    try:
        wall, cpu = time.perf_counter(), time.process_time()
        _, result = fit_run(run, FitOptions(multiple_scattering=True, ms_seed=seed))
        return result, time.perf_counter() - wall, time.process_time() - cpu
    finally:
        lobe.walk_both_ways, orders_module.MS_REWALK_SIGMA = both_ways, threshold


def row(run: Path, truth: float, forward_only: bool, rewalk: bool) -> str:
    """One fit's figures over SEEDS fit seeds on the same run."""
    fits = [fitted(run, forward_only, rewalk, seed) for seed in range(SEEDS)]
    values = np.array([[*result.param("alpha"), result.chi2_dof_fit, result.chi2_dof_heldout,
                        wall, cpu] for result, wall, cpu in fits])
    alpha, sigma = values[:, 0], values[:, 1]
    chi2_fit, chi2_held, wall, cpu = np.median(values[:, 2:], axis=0)
    return (f"{median_range(alpha, '.7f'):>33} {np.median(sigma):7.1e} "
            f"{median_range((alpha - truth) / sigma, '+.2f'):>20} {chi2_fit:8.3f} "
            f"{chi2_held:6.3f} {wall:7.2f} {cpu:6.2f}")


def main() -> None:
    """Print the table."""
    print(f"load average {os.getloadavg()[0]:.1f}; {THREADS} threads; {SEEDS} fit seeds on each "
          f"scan: alpha and pull as the median [min, max] over them, the rest medians")
    print(f"{'sample':>13} {'bench walks':>11} {'fit':>13} {'alpha':>33} {'sigma':>7} "
          f"{'pull':>20} {'chi2 fit':>8} {'held':>6} {'wall s':>7} {'CPU s':>6}")
    with tempfile.TemporaryDirectory() as tmp:
        for name, truth in SAMPLES:
            for bench_walks, fits in FITS.items():
                run = scan(name, Path(tmp), bench_walks)
                shown = bench_walks or int(re.search(r"^ms_walks = (\d+)", (
                    ROOT / "examples" / "instruments" / f"sim-walter-{name}.toml").read_text(),
                    flags=re.M).group(1))
                for label, forward_only, rewalk in fits:
                    print(f"{name:>13} {shown:>11} {label:>13} "
                          f"{row(run, truth, forward_only, rewalk)}", flush=True)


if __name__ == "__main__":
    main()
