"""The shipped angle calibration's offset pulls over emulated bench seeds, beside honest sigmas'.

As a user runs it: `gonio scan examples/plans/calib-angles.toml --sim --time-scale inf`, then
`gonio calibrate build RUN`, on examples/instruments/sim-serial.toml (no alignment errors: both
offsets are truly 0) with its `[sim] seed` set to 1..--seeds; per seed the sample and arm
offsets (1e-6 deg) with their sigmas, pulls offset / sigma and the fit's chi2/dof; then the
pulls' rms and share beyond 2 beside the baseline of sigmas that are right (rms 1, 4.6 %).
An instant run's times come from its virtual clock, so the figures are the same on every
machine. About 10 s per seed. docs/fitting.md ("The shipped plan as a user runs it") quotes it.
Run: python bench/calib_angle_pulls.py [--seeds 32]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / "examples" / "instruments" / "sim-serial.toml"
PLAN = ROOT / "examples" / "plans" / "calib-angles.toml"
HONEST_BEYOND_2 = math.erfc(2.0 / math.sqrt(2.0))  # share of N(0, 1) beyond 2


def gonio(*args: str) -> str:
    """Run the gonio CLI of this checkout; its stdout (a failure ends the script with its
    stderr)."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    done = subprocess.run([sys.executable, "-m", "gonio_cli", *args], cwd=ROOT, env=env,
                          capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"gonio {' '.join(args)}: exit {done.returncode}\n{done.stderr}")
    return done.stdout


def with_line(text: str, pattern: str, line: str) -> str:
    """text with its one line matching pattern (a regex anchored at a line start) replaced."""
    out, n = re.subn(pattern, line, text, count=1, flags=re.MULTILINE)
    if n != 1:
        raise SystemExit(f"no line {pattern!r} to set")
    return out


def angles_of_seed(seed: int, tmp: Path) -> dict:
    """The `angles` table of the calibration built from the shipped plan on bench seed `seed`
    (the config holds no relative paths, so its copy may live in tmp)."""
    config = tmp / f"sim-serial-{seed}.toml"
    config.write_text(with_line(CONFIG.read_text(), r"^seed = .*$", f"seed = {seed}"))
    plan = tmp / f"calib-angles-{seed}.toml"
    plan.write_text(with_line(PLAN.read_text(), r"^instrument = .*$",
                              f"instrument = {json.dumps(str(config))}"))
    run = gonio("scan", str(plan), "--sim", "--time-scale", "inf", "--no-plot", "--no-progress",
                "--out", str(tmp / "runs")).strip().splitlines()[-1]
    cal = tmp / f"cal-{seed}.json"
    gonio("calibrate", "build", run, "--out", str(cal))
    return json.loads(cal.read_text())["angles"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=32)
    args = ap.parse_args()
    print(f"{'seed':>4} {'sample offset':>15} {'pull':>6} {'arm offset':>13} {'pull':>6} "
          f"{'chi2/dof':>8}")
    pulls = []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(1, args.seeds + 1):
            angles = angles_of_seed(seed, Path(tmp))
            row = [f"{seed:>4}"]
            for key, width in (("sample_offset_deg", 15), ("arm_offset_deg", 13)):
                value, sigma = angles[key]["value"], angles[key]["sigma"]
                pulls.append(value / sigma)
                row.append(f"{f'{value * 1e6:+.1f} +- {sigma * 1e6:.1f}':>{width}} "
                           f"{value / sigma:+6.2f}")
            print(" ".join(row), f"{angles['fit']['chi2_dof']:8.2f}", flush=True)
    p = np.array(pulls)
    print(f"{len(p)} pulls: rms {np.sqrt(np.mean(p ** 2)):.2f} (sample "
          f"{np.sqrt(np.mean(p[0::2] ** 2)):.2f}, arm {np.sqrt(np.mean(p[1::2] ** 2)):.2f}), "
          f"{np.sum(np.abs(p) > 2)} beyond 2 ({np.mean(np.abs(p) > 2):.1%}); "
          f"honest sigmas: rms 1.00, {HONEST_BEYOND_2:.1%} beyond 2")


if __name__ == "__main__":
    main()
