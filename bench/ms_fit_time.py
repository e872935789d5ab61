"""The multiple-scattering fit's time against the single-scattering fit's, before and after.

Both Walter plans (ground glass GGX 0.394, acid-etched GGX 0.553) are scanned afresh on the
emulated bench (walter_ms_fits.scan: the example plans, `gonio scan --sim --time-scale inf`),
and each run is fitted as `gonio fit RUN` and `gonio fit RUN --multiple-scattering` do
(calibration.pipeline.fit_run: the reduction's slope fit, then the fit) by the code at BEFORE
(its tree from `git archive`) and by this checkout, each in its own process, on the same run in
the same invocation. A process first fits once without timing (single scattering) and loads the
walk kernels, then times the fits `--repeats` times in turn (the fastest of each). Times: wall
and CPU seconds (the walks run on keyed.THREADS threads; the machine is shared, so compare the
ratios of one row). Model error against the data's noise: alpha +- sigma, its pull from the
microsurface's alpha, chi2/dof on the fitted (normal incidence) and held-out points; "shift":
this checkout's alpha minus BEFORE's, in BEFORE's sigma.
Run: python bench/ms_fit_time.py [--repeats 1] [--runs GROUND ACID]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _git_baseline import ROOT, tree_at

#: The commit whose fit is "before" (the fit as issue 36 measured it: 9x single scattering).
BEFORE = "f5df95b"
SAMPLES = (("ground-glass", 0.394), ("acid-etched", 0.553))


def fit_times(run: str, repeats: int) -> dict[str, dict[str, float]]:
    """In this process (whatever calibration PYTHONPATH gives): the run fitted with single and
    multiple scattering, `repeats` times each in turn after a warm-up; per kind the fastest
    wall and CPU seconds and the fit's alpha, sigma, chi2/dof fitted and held out."""
    import numpy as np

    from calibration.fit import FitOptions
    from calibration.fit.orders import walked_orders
    from calibration.pipeline import fit_run

    fit_run(run, FitOptions())  # numba's kernels loaded, caches warm
    walked_orders("ggx", 0.4, 1.51, None, np.array([[0.0, 0.0, 1.0]]),
                  np.array([[0.6, 0.0, -0.8]]), 2, 0)
    out: dict[str, dict[str, float]] = {}
    for _ in range(repeats):
        for kind in ("ss", "ms"):
            wall, cpu = time.perf_counter(), time.process_time()
            _, result = fit_run(run, FitOptions(multiple_scattering=kind == "ms"))
            wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
            value, sigma = result.param("alpha")
            best = out.get(kind, {"wall": np.inf, "cpu": np.inf})
            out[kind] = {"wall": min(wall, best["wall"]), "cpu": min(cpu, best["cpu"]),
                         "alpha": value, "sigma": sigma, "chi2": result.chi2_dof_fit,
                         "held": result.chi2_dof_heldout, "distribution": result.distribution}
    return out


def measured(tree: Path, run: Path, repeats: int) -> dict[str, dict[str, float]]:
    """fit_times of run by the code in tree, in a process of its own."""
    env = dict(os.environ, PYTHONPATH=str(tree))
    done = subprocess.run([sys.executable, __file__, "--fit", str(run), "--repeats",
                           str(repeats)], env=env, capture_output=True, text=True, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def row(name: str, truth: float, code: str, fits: dict, shift: str) -> str:
    """One table row: times, ratios, and each fit's alpha, pull and chi2/dof."""
    ss, ms = fits["ss"], fits["ms"]
    text = (f"{name:>12} {code:>7} {ss['wall']:7.1f} {ss['cpu']:6.1f} {ms['wall']:7.1f} "
            f"{ms['cpu']:6.1f} {ms['wall'] / ss['wall']:6.2f} {ms['cpu'] / ss['cpu']:6.2f}")
    for fit in (ss, ms):
        pull = (fit["alpha"] - truth) / fit["sigma"]
        text += (f"  {fit['alpha']:.6f} +- {fit['sigma']:.1e} ({pull:+6.2f}) {fit['chi2']:9.3g}"
                 f" {fit['held']:8.3g}")
    return text + f" {shift:>6}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=1)
    parser.add_argument("--runs", nargs=2, type=Path, help="runs of the two plans to fit "
                        "(ground glass, acid-etched) instead of scanning them afresh")
    parser.add_argument("--fit", help=argparse.SUPPRESS)  # one process's fits (measured)
    args = parser.parse_args()
    if args.fit:
        print(json.dumps(fit_times(args.fit, args.repeats)))
        return
    sys.path.insert(0, str(ROOT))
    from walter_ms_fits import scan

    from model.bsdf.multiple_scattering.keyed import THREADS

    print(f"load average {os.getloadavg()[0]:.1f}; {THREADS} walk threads; before = {BEFORE}; "
          f"fastest of {args.repeats}; times in s; alpha +- sigma (pull), chi2/dof fitted, held")
    print(f"{'sample':>12} {'code':>7} {'SS wall':>7} {'CPU':>6} {'MS wall':>7} {'CPU':>6} "
          f"{'MS/SS':>6} {'CPU':>6}  {'single scattering':<46}{'multiple scattering':<46} shift")
    with tempfile.TemporaryDirectory() as tmp:
        old = tree_at(BEFORE, Path(tmp))
        for k, (name, truth) in enumerate(SAMPLES):
            run = args.runs[k] if args.runs else scan(name, Path(tmp), None)
            before = measured(old, run, args.repeats)
            print(row(name, truth, "before", before, ""), flush=True)
            after = measured(ROOT, run, args.repeats)
            shift = (after["ms"]["alpha"] - before["ms"]["alpha"]) / before["ms"]["sigma"]
            print(row(name, truth, "after", after, f"{shift:+.2f}"), flush=True)


if __name__ == "__main__":
    main()
