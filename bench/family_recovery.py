"""Each model family recovered end to end on the emulated bench: the shipped family plans
(examples/plans/matte-paint, white-reference, abg-scatterer) scanned with bench seeds 1..N,
reduced and fitted with the sample kind's family selection (`gonio fit RUN`); per plan, how
often the truth's family was chosen and each parameter's pulls (fitted - truth) / sigma
(mean, spread), beside the baseline in the same run: the microfacet-only fit of the same runs
(what `gonio fit --family microfacet` gives, the only model before the families; a panel
without an index at eta 1.5).
Run: python bench/family_recovery.py [--seeds 8]
"""

from __future__ import annotations

import argparse
import os
import re
import sys
import tempfile
import tomllib
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "tests" / "fitting")]

from fitting_bench_runs import scan  # noqa: E402

from calibration.fit import FitError, FitOptions, select  # noqa: E402
from calibration.pipeline import fit_run  # noqa: E402

PLANS = ("matte-paint", "white-reference", "abg-scatterer")


def seeded_copy(name: str, seed: int, tmp: Path) -> tuple[Path, Path, dict]:
    """The plan `name` and its instrument copied to tmp with [sim] seed = seed; the truth."""
    plan = ROOT / "examples" / "plans" / f"{name}.toml"
    text = plan.read_text()
    source = (plan.parent / re.search(r'^instrument = "(.+)"', text, re.M).group(1)).resolve()
    config = source.read_text()
    truth = tomllib.loads(config)["sim"]["sample"]
    inst = tmp / f"{name}-{seed}-instrument.toml"
    inst.write_text(re.sub(r"^seed = \d+", f"seed = {seed}", config, count=1, flags=re.M))
    copied = tmp / f"{name}-{seed}.toml"
    copied.write_text(re.sub(r'^instrument = ".+"', f'instrument = "{inst}"', text, count=1,
                             flags=re.M))
    return copied, inst, truth


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=8)
    args = ap.parse_args()
    print(f"load average {os.getloadavg()[0]:.1f}; bench seeds 1-{args.seeds}")
    print(f"{'plan':<16} {'chosen (truth)':<26} {'parameter':<9} {'truth':>8} {'pull mean':>9} "
          f"{'spread':>6} {'chi2/dof':>9} {'microfacet-only chi2/dof':>25}")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for name in PLANS:
            pulls: dict[str, list[float]] = {}
            chosen, chi2, baseline = [], [], []
            for seed in range(1, args.seeds + 1):
                plan, inst, truth = seeded_copy(name, seed, tmp)
                run = scan(plan, inst, tmp / "runs")
                data, result = fit_run(run)
                chosen.append(result.family)
                chi2.append(result.chi2_dof_fit)
                for p in result.names:
                    if p in truth:
                        value, sigma = result.param(p)
                        pulls.setdefault(p, []).append((value - truth[p]) / sigma)
                try:
                    baseline.append(select(data, FitOptions(
                        families=("microfacet",), eta=truth.get("eta", 1.5))).chi2_dof_fit)
                except FitError:
                    baseline.append(float("nan"))
            right = sum(c == truth["family"] for c in chosen)
            said = f"{right}/{len(chosen)} {truth['family']}"
            for p, values in pulls.items():
                v = np.array(values)
                print(f"{name:<16} {said:<26} {p:<9} {truth[p]:>8.4g} {v.mean():>+9.2f} "
                      f"{v.std(ddof=1):>6.2f} {np.median(chi2):>9.3g} "
                      f"{np.nanmedian(baseline):>25.3g}", flush=True)


if __name__ == "__main__":
    main()
