"""SIGKILL a scan at random moments, resume it (again and again): every completed point is
kept, none is duplicated, and the finished run has exactly the points of an uninterrupted
run of the same plan and seed."""

import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from gonio_testkit import ROOT, fast_config, gonio_cli, run_dir_of, write_toml

from gonio.store import open_run

PLAN = {"name": "kill", "repeats": 2, "dark": {"every": 15}, "beam": {"every": 30}, "grid": [
    {"side": ["reflection", "transmission"], "theta_i_deg": [10.0, 40.0],
     "theta_o_deg": {"start": -50.0, "stop": 50.0, "step": 10.0}, "skip_forbidden": True}]}
POSITION_FIELDS = ("index", "kind", "side", "repeat", "point", "sample_deg", "arm_deg",
                   "elevation_deg", "azimuth_deg", "theta_i_deg", "phi_i_deg", "theta_o_deg",
                   "phi_o_deg", "plan_theta_i_deg", "plan_theta_o_deg", "plan_phi_o_deg")


def lines_in(run_root):
    files = list(run_root.glob("*/readings.jsonl"))
    return (files[0].read_bytes().count(b"\n"), files[0].parent) if files else (0, None)


def start_and_kill(args, run_root, kill_after, extra_sleep_s):
    """Start `gonio ARGS`, SIGKILL it once `kill_after` readings are stored (+ a little)."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen([sys.executable, "-m", "gonio.cli", *map(str, args)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env)
    deadline = time.monotonic() + 60
    try:
        while lines_in(run_root)[0] < kill_after and proc.poll() is None:
            assert time.monotonic() < deadline, "scan made no progress"
            time.sleep(0.002)
        time.sleep(extra_sleep_s)
        proc.send_signal(signal.SIGKILL)
    finally:
        proc.communicate(timeout=30)
    return proc.returncode


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """The uninterrupted run."""
    root = tmp_path_factory.mktemp("kill")
    write_toml(root / "instrument.toml", fast_config())
    write_toml(root / "plan.toml", {**PLAN, "instrument": "instrument.toml"})
    proc = gonio_cli("scan", root / "plan.toml", "--sim", "--out", root / "ref", "--no-plot")
    assert proc.returncode == 0, proc.stderr
    return root, open_run(run_dir_of(proc)).readings()


@pytest.mark.parametrize("chain_seed", [11, 12])
def test_sigkill_and_resume_keeps_every_point_once(reference, tmp_path, chain_seed):
    root, ref = reference
    rng = np.random.default_rng(chain_seed)
    n = len(ref)
    kills = np.sort(rng.choice(np.arange(1, n - 25), size=3, replace=False))  # margin: kill first
    run_root = tmp_path / "runs"
    args = ["scan", root / "plan.toml", "--sim", "--out", run_root, "--no-plot",
            "--no-progress"]
    run_dir = None
    for kill_after in kills:
        code = start_and_kill(args, run_root, kill_after, rng.uniform(0.0, 0.01))
        count, run_dir = lines_in(run_root)
        assert code == -signal.SIGKILL, "the scan finished before it could be killed"
        stored = open_run(run_dir).readings()
        assert len(stored) >= kill_after
        assert list(stored["index"]) == list(range(len(stored)))  # nothing lost or doubled
        args = ["scan", "--resume", run_dir, "--no-plot", "--no-progress"]
    proc = gonio_cli(*args)
    assert proc.returncode == 0, proc.stderr
    assert run_dir_of(proc) == run_dir
    run = open_run(run_dir)
    got = run.readings()
    assert run.meta["status"] == "completed"
    assert len(run.meta["sessions"]) == len(kills) + 1
    assert len(got) == n
    for field in POSITION_FIELDS:
        np.testing.assert_array_equal(got[field], ref[field], err_msg=field)
    assert (got["t_s"][1:] >= got["t_s"][:-1]).all()


def test_resume_of_a_completed_run_is_refused(reference):
    root, _ = reference
    run_dir = next((root / "ref").iterdir())
    proc = gonio_cli("scan", "--resume", run_dir)
    assert proc.returncode == 2 and "already completed" in proc.stderr
