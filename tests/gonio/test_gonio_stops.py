"""Every way a scan ends stops every axis and records why (real processes and signals):
SIGTERM on the two-process rehearsal leaves the emulated arm where it was, not at its target;
SIGHUP aborts the same way; a SIGINT the moment the run directory appears pauses as any other
does; one while the modules load is one line; the axes of a lost device are recorded as not
stopped."""

import json
import os
import signal
import subprocess
import sys

import pytest
from gonio_testkit import (
    ROOT,
    arm_on_its_way,
    esp_arm_at_rest,
    fast_config,
    gonio_cli,
    pointed,
    run_dir_of,
    serving,
    start_gonio,
    wait_for_lines,
    write_plan,
    write_toml,
)
from waiting import wait_until

from gonio.config import load_config
from gonio.plan import build_schedule, load_plan
from gonio.store import open_run

FAR = {"name": "far", "grid": [{"theta_i_deg": [0.0], "theta_o_deg": [10.0, 80.0, 20.0, 85.0]}]}
ENV = {**os.environ, "PYTHONPATH": str(ROOT)}


def scan(*args: object, stdin=subprocess.DEVNULL) -> subprocess.Popen:
    return start_gonio("scan", *args, "--no-plot", "--no-progress", stdin=stdin)


def test_sigterm_stops_the_arm_of_a_two_process_rehearsal(tmp_path):
    cfg = fast_config(time_scale=1.0)  # real time: 10 -> 80 deg takes 2.6 s
    with serving(write_toml(tmp_path / "emulated.toml", cfg)) as (endpoints, bench):
        plan = write_plan(tmp_path, FAR, pointed(cfg, endpoints))
        proc = scan(plan, "--out", tmp_path / "runs")
        arm_on_its_way(bench, 80.0, 30.0)  # from the first target to the second
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=30)
        assert proc.returncode == 128 + signal.SIGTERM, err
        first = esp_arm_at_rest(endpoints["esp"][1])
    targets = build_schedule(load_plan(plan), load_config(tmp_path / "plan-instrument.toml")
                             ).readings["arm_deg"]
    assert min(abs(targets - first)) > 1.0, (first, targets)  # stopped on the way
    run = open_run(run_dir_of(subprocess.CompletedProcess([], 0, out, err)))
    assert (run.meta["status"], run.meta["reason"]) == ("aborted", "SIGTERM")
    assert "unstopped" not in run.meta and err.strip().endswith(" readings: SIGTERM")


def test_sighup_aborts_and_the_run_resumes(tmp_path):
    proc = scan(write_plan(tmp_path, FAR, fast_config(time_scale=5.0)), "--sim", "--out",
                tmp_path / "runs")
    wait_for_lines(tmp_path / "runs", 1, proc)
    proc.send_signal(signal.SIGHUP)
    out, err = proc.communicate(timeout=30)
    assert proc.returncode == 128 + signal.SIGHUP, err
    run_dir = run_dir_of(subprocess.CompletedProcess([], 0, out, err))
    assert open_run(run_dir).meta["reason"] == "SIGHUP"
    done = gonio_cli("scan", "--resume", run_dir, "--no-plot")
    assert done.returncode == 0, done.stderr
    assert [s["status"] for s in open_run(run_dir).meta["sessions"]] == ["aborted", "completed"]


def test_sigint_as_the_run_directory_appears_pauses_and_end_of_input_aborts(tmp_path):
    runs = tmp_path / "runs"
    proc = scan(write_plan(tmp_path, FAR, fast_config()), "--sim", "--out", runs)
    wait_until(lambda: list(runs.glob("*/meta.json")) or proc.poll() is not None,
               what="the run directory", poll_s=0.001)
    assert proc.poll() is None, proc.communicate()
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert "Traceback" not in err and "paused: [r]esume or [a]bort?" in err
    run = open_run(run_dir_of(subprocess.CompletedProcess([], 0, out, err)))
    assert run.meta["status"] == "aborted" and run.meta["reason"] == "aborted by the user"
    assert [p.name for p in runs.iterdir()] == [run.path.name]  # no .partial left behind


@pytest.mark.parametrize("module", ["argparse", "numpy"])
def test_sigint_while_loading_is_one_line(module):
    """SIGINT the moment `module` is first imported: in gonio_cli.main's own imports (argparse)
    and in a command's (numpy)."""
    code = ("import os, runpy, signal, sys\n"
            "def hook(event, args):\n"
            f"    if event == 'import' and args[0] == {module!r}:\n"
            "        os.kill(os.getpid(), signal.SIGINT)\n"
            "sys.addaudithook(hook)\n"
            "sys.argv = ['gonio', 'plan', 'examples/plans/demo.toml']\n"
            "runpy.run_module('gonio_cli', run_name='__main__', alter_sys=True)\n")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          cwd=ROOT, env=ENV, timeout=60)
    assert proc.returncode == 130, proc.stderr
    assert proc.stderr.strip() in ("gonio: interrupted", "gonio plan: interrupted"), proc.stderr


def test_a_lost_device_is_recorded_as_not_stopped(tmp_path):
    # the controller of both axes hangs up during the second reading (the scan takes 30 replies)
    cfg = fast_config(faults={"esp": {"disconnect_after": 24}})
    proc = gonio_cli("scan", write_plan(tmp_path, FAR, cfg), "--sim", "--out",
                     tmp_path / "runs", "--no-plot")
    assert proc.returncode == 1, proc.stderr
    meta = json.loads((run_dir_of(proc) / "meta.json").read_text())
    assert meta["status"] == "failed" and meta["reason"].startswith("reading ")
    assert sorted(meta["unstopped"]) == ["arm", "sample"]
    assert "; could not stop: sample: esp: " in meta["reason"]
