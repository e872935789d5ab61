"""The emulated Walter samples' alphas three ways: the microsurface's ([sim.sample] alpha), the
single-scattering-equivalent one (Walter's method: the default `gonio fit`, single scattering at
normal incidence) and what a multiple-scattering fit returns.

For each sample the bench's exact expectation at the example plan's normal-incidence readings,
weighted by the emulated meter's predicted noise (tests/fitting/single_scattering_alpha.py),
is fitted with the default options and with --multiple-scattering's; the single-scattering
fit is repeated with the bench's tables at WALKS walks in place of the config's 2^24 (walked from
SEEDS seeds: alpha's shift as the median [min, max] over them), and with
only the sample's own distribution, the two economies of
tests/fitting/test_fitting_walter_single_scattering_alpha.py. With --scan SAMPLE the example
plan is also scanned (`gonio scan --sim --time-scale inf`, the default table cache) and fitted
by `gonio fit RUN --json`, with and without --multiple-scattering. The first run on a machine
walks the tables at normal incidence (2^24 walks: minutes per sample; a scan every incidence).
Run: python bench/walter_single_scattering.py [--scan ground-glass ...]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "tests" / "fitting")]

from _seeds import SEEDS, median_range  # noqa: E402
from single_scattering_alpha import (  # noqa: E402
    SAMPLES,
    normal_incidence_expectation,
    sample_table,
    single_scattering_fit,
)

from calibration.fit import FitOptions, fit  # noqa: E402
from gonio_cli import emulator_truth  # noqa: E402

WALKS = (1 << 14, 1 << 16, 1 << 18, 1 << 20)


def gonio(*args: str) -> str:
    """stdout of a `gonio` command run from the checkout."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    return subprocess.run([sys.executable, "-m", "gonio_cli", *args], env=env, check=True,
                          capture_output=True, text=True, cwd=ROOT).stdout


def scanned(sample: str, out: Path) -> tuple[dict, dict]:
    """`gonio fit RUN --json` of a fresh scan of the sample's example plan: (single
    scattering, --multiple-scattering)."""
    plan = ROOT / "examples" / "plans" / f"walter-{sample}.toml"
    run = gonio("scan", str(plan), "--sim", "--time-scale", "inf", "--out", str(out),
                "--no-plot", "--no-progress").strip().splitlines()[-1]
    return (json.loads(gonio("fit", run, "--json")),
            json.loads(gonio("fit", run, "--json", "--multiple-scattering")))


def alpha_of(out: dict) -> str:
    """alpha +- sigma of a `gonio fit --json` result."""
    p = out["parameters"]["alpha"]
    return f"{out['distribution']} {p['value']:.6f} +- {p['sigma']:.2g}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scan", nargs="*", default=(), choices=SAMPLES, metavar="SAMPLE",
                        help=f"also scan and fit these samples ({', '.join(SAMPLES)})")
    args = parser.parse_args()
    emulator_truth.install()
    print("sample        microsurface  single scattering (chi2/dof, preferred by dchi2)   "
          "multiple scattering    shipped")
    for sample in SAMPLES:
        table = sample_table(sample)
        data = normal_incidence_expectation(sample)
        single = fit(data, FitOptions())
        multiple = fit(data, FitOptions(multiple_scattering=True))
        print(f"{sample:<13} {table['distribution']} {table['alpha']:<8g} "
              f"{single.distribution} {single.values[0]:.6f} +- {single.errors[0]:.2g} "
              f"({single.chi2_dof_fit:.3g}, {single.preferred_by:.3g})   "
              f"{multiple.distribution} {multiple.values[0]:.6f} +- {multiple.errors[0]:.2g}   "
              f"{table['single_scattering_alpha']:g} +- {table['single_scattering_alpha_u']:g}")
        own = (table["distribution"],)
        shifts = [[single_scattering_fit(sample, walks, own, seed).values[0] - single.values[0]
                   for seed in range(SEEDS)] for walks in WALKS]
        print(f"{'':13} its own distribution alone: "
              f"{single_scattering_fit(sample, None, own).values[0]:.6f}; "
              f"tables at 2^14, 2^16, 2^18, 2^20 walks ({SEEDS} seeds each): alpha "
              + ", ".join(median_range(row, "+.1e") for row in shifts))
    with tempfile.TemporaryDirectory() as tmp:
        for sample in args.scan:
            single, multiple = scanned(sample, Path(tmp))
            print(f"{sample:<13} scanned: gonio fit {alpha_of(single)} "
                  f"(chi2/dof {single['chi2_dof_fit']:.3g}); --multiple-scattering "
                  f"{alpha_of(multiple)} (chi2/dof {multiple['chi2_dof_fit']:.3g})")


if __name__ == "__main__":
    main()
