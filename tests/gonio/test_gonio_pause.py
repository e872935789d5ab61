"""Ctrl-C during a scan (a real SIGINT to a `gonio scan` process): the first pauses at the
next point and the prompt resumes or aborts; a second Ctrl-C aborts; an aborted run resumes."""

import json
import os
import signal
import subprocess
import sys

from gonio_testkit import ROOT, Channel, fast_config, gonio_cli, run_dir_of, token_of, write_toml
from waiting import wait_until

from gonio.store import open_run

PLAN = {"name": "pause", "grid": [{"side": "reflection", "theta_i_deg": [20.0, 40.0],
                                   "theta_o_deg": {"start": -80, "stop": 80, "step": 12},
                                   "skip_forbidden": True}]}


def start(tmp_path):
    cfg = fast_config(time_scale=8.0)  # slow enough to interrupt, about two seconds in all
    write_toml(tmp_path / "cfg.toml", cfg)
    plan = write_toml(tmp_path / "plan.toml", {**PLAN, "instrument": "cfg.toml"})
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.Popen([sys.executable, "-m", "gonio_cli", "scan", str(plan), "--sim",
                             "--out", str(tmp_path / "runs"), "--no-plot", "--no-progress"],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env)


def wait_for(tmp_path, predicate):
    """Until a run's meta.json and readings count satisfy predicate; returns its directory."""
    def run_dir():
        for meta in (tmp_path / "runs").glob("*/meta.json"):
            try:
                data = json.loads(meta.read_text())
            except ValueError:
                continue
            lines = (meta.parent / "readings.jsonl").read_bytes().count(b"\n")
            if predicate(data, lines):
                return meta.parent
        return None

    return wait_until(run_dir, what="the run's state", poll_s=0.01)


def pausing(proc: subprocess.Popen) -> None:
    """Until the scan has taken a Ctrl-C as a pause: its `pausing after this point` line."""
    for line in proc.stderr:
        if line.startswith("pausing after this point"):
            return
    raise AssertionError("the scan ended without pausing")


def test_ctrl_c_pauses_and_resume_continues(tmp_path):
    proc = start(tmp_path)
    token, _ = token_of(proc)
    wait_for(tmp_path, lambda m, n: n >= 3)
    proc.send_signal(signal.SIGINT)
    pausing(proc)
    run_dir = wait_for(tmp_path, lambda m, n: m["status"] == "paused")
    paused_at = len(open_run(run_dir))
    channel = Channel(run_dir, token)
    try:
        channel.stays_paused(paused_at)
    finally:
        channel.close()
    assert len(open_run(run_dir)) == paused_at  # nothing measured while paused
    out, err = proc.communicate("r\n", timeout=60)
    assert proc.returncode == 0, err
    assert "paused: [r]esume or [a]bort?" in err
    assert run_dir_of(subprocess.CompletedProcess([], 0, out, err)) == run_dir
    run = open_run(run_dir)
    assert run.meta["status"] == "completed" and len(run) == run.meta["planned"]


def test_second_ctrl_c_aborts_and_the_run_resumes_later(tmp_path):
    proc = start(tmp_path)
    wait_for(tmp_path, lambda m, n: n >= 3)
    proc.send_signal(signal.SIGINT)
    wait_for(tmp_path, lambda m, n: m["status"] == "paused")
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=30)
    assert proc.returncode == 130
    run_dir = run_dir_of(subprocess.CompletedProcess([], 0, out, err))
    run = open_run(run_dir)
    assert run.meta["status"] == "aborted" and "aborted by the user" in run.meta["reason"]
    stored = run.readings()
    assert list(stored["index"]) == list(range(len(stored)))
    done = gonio_cli("scan", "--resume", run_dir, "--no-plot")
    assert done.returncode == 0, done.stderr
    run = open_run(run_dir)
    assert run.meta["status"] == "completed" and len(run) == run.meta["planned"]
    assert [s["status"] for s in run.meta["sessions"]] == ["aborted", "completed"]


def test_ctrl_c_twice_in_a_move_aborts_at_once(tmp_path):
    proc = start(tmp_path)
    wait_for(tmp_path, lambda m, n: n >= 2)
    proc.send_signal(signal.SIGINT)
    pausing(proc)  # the first taken: the second is not merged into it
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=30)
    assert proc.returncode == 130, err
    run = open_run(run_dir_of(subprocess.CompletedProcess([], 0, out, err)))
    assert run.meta["status"] == "aborted"
    assert len(run) < run.meta["planned"]
