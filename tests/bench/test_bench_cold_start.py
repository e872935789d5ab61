"""A first scan on a fresh machine (no compiled kernels cached yet) must not time out: the
emulators build the model's kernels before serving, not during the detector's first reading."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

PLAN = """
name = "cold-start"
instrument = "{instrument}"
averaging = 1

[[point]]
side = "transmission"
theta_i_deg = 0.0
theta_o_deg = 10.0
"""


@pytest.mark.slow
def test_first_reading_with_an_empty_kernel_cache_is_within_the_modbus_timeout(tmp_path):
    plan = tmp_path / "plan.toml"
    plan.write_text(PLAN.format(instrument=ROOT / "examples/instruments/sim-modbus.toml"))
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba-cache")}
    done = subprocess.run(
        [sys.executable, "-m", "gonio_cli", "scan", str(plan), "--sim", "--no-plot", "--out",
         str(tmp_path / "runs")], capture_output=True, text=True, timeout=300, env=env, cwd=ROOT)
    assert done.returncode == 0, done.stderr
    assert any((tmp_path / "numba-cache").rglob("*.nbi")), "the kernels were not compiled afresh"
