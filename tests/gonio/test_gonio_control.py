"""The control channel of a real `gonio scan` process over its real Unix socket: status, pause
(readings stop growing, meta.json says paused), resume, abort (axes stopped on their way,
status aborted), a bad token refused with nothing done, the socket mode 0600 and removed when
the scan ends; the pause waits on the channel even with no terminal input."""

import os
import signal
import stat
import subprocess
import sys

from gonio_testkit import (
    ROOT,
    Channel,
    arm_on_its_way,
    esp_arm_at_rest,
    fast_config,
    pointed,
    serving,
    token_of,
    write_plan,
    write_toml,
)
from waiting import wait_until

from gonio.config import load_config
from gonio.control import SOCKET, connect
from gonio.plan import build_schedule, load_plan
from gonio.store import open_run

PLAN = {"name": "control", "grid": [{"side": "reflection", "theta_i_deg": [20.0, 40.0],
                                     "theta_o_deg": {"start": -80, "stop": 80, "step": 12},
                                     "skip_forbidden": True}]}
FAR = {"name": "far", "grid": [{"theta_i_deg": [0.0], "theta_o_deg": [10.0, 80.0, 20.0, 85.0]}]}
ENV = {**os.environ, "PYTHONPATH": str(ROOT)}


def scan(plan, *args) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "gonio_cli", "scan", str(plan), *map(str, args),
                             "--no-plot", "--no-progress"], stdin=subprocess.DEVNULL,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=ENV)


def test_status_pause_resume_abort_and_a_bad_token(tmp_path):
    proc = scan(write_plan(tmp_path, PLAN, fast_config(time_scale=8.0)), "--sim",
                "--out", tmp_path / "runs")
    token, run_dir = token_of(proc)
    assert stat.S_IMODE(os.stat(os.path.join(run_dir, SOCKET)).st_mode) == 0o600
    assert token not in "".join(p.read_text() for p in tmp_path.glob("runs/*/*.json"))
    channel = Channel(run_dir, token)
    try:
        first = channel.ask("status")
        assert first["ok"] and first["state"] in ("starting", "running")
        first = wait_until(lambda: (s := channel.ask("status"))["state"] == "running" and s,
                           what="a running scan")
        assert first["planned"] > 20
        assert channel.ask("pause", "0" * 32) == {"ok": False, "error": "bad token"}
        assert channel.ask("status", "") == {"ok": False, "error": "bad token"}
        wait_until(lambda: channel.ask("status")["readings"] >= first["readings"] + 2,
                   what="two more readings")
        assert channel.ask("status")["state"] == "running"  # the bad pause did nothing

        assert channel.ask("pause")["state"] in ("pausing", "paused")
        paused = wait_until(lambda: (s := channel.ask("status"))["state"] == "paused" and s,
                            what="the run paused")
        # meta.json follows the state (the engine's Paused event)
        wait_until(lambda: open_run(run_dir).meta["status"] == "paused", what="meta.json paused")
        channel.stays_paused(paused["readings"])  # no terminal input: it waits on the channel
        assert len(open_run(run_dir)) == paused["readings"]

        assert channel.ask("resume")["state"] == "running"
        wait_until(lambda: channel.ask("status")["readings"] > paused["readings"],
                   what="a reading after the resume")
        assert channel.ask("resume") == {"ok": False, "error": "not paused (running)"}
        assert channel.ask("abort")["state"] == "stopping"
    finally:
        channel.close()
    out, err = proc.communicate(timeout=30)
    assert proc.returncode == 130, err
    assert out.strip().splitlines()[-1] == run_dir
    run = open_run(run_dir)
    assert (run.meta["status"], run.meta["reason"]) == ("aborted",
                                                        "aborted from the control channel")
    assert "unstopped" not in run.meta and len(run) < run.meta["planned"]
    assert not os.path.exists(os.path.join(run_dir, SOCKET))


def test_abort_from_the_channel_stops_the_arm_on_its_way(tmp_path):
    cfg = fast_config(time_scale=1.0)  # real time: 10 -> 80 deg takes 2.6 s
    with serving(write_toml(tmp_path / "emulated.toml", cfg)) as (endpoints, bench):
        plan = write_plan(tmp_path, FAR, pointed(cfg, endpoints))
        proc = scan(plan, "--out", tmp_path / "runs")
        token, run_dir = token_of(proc)
        channel = Channel(run_dir, token)
        try:
            arm_on_its_way(bench, 80.0, 30.0)  # from the first target to the second
            assert channel.ask("abort")["ok"]
        finally:
            channel.close()
        _, err = proc.communicate(timeout=30)
        assert proc.returncode == 130, err
        first = esp_arm_at_rest(endpoints["esp"][1])
    targets = build_schedule(load_plan(plan), load_config(tmp_path / "plan-instrument.toml")
                             ).readings["arm_deg"]
    assert min(abs(targets - first)) > 1.0, (first, targets)  # stopped on the way
    run = open_run(run_dir)
    assert (run.meta["status"], run.meta["reason"]) == ("aborted",
                                                        "aborted from the control channel")


def test_a_run_that_is_not_running_cannot_be_reached(tmp_path):
    proc = scan(write_plan(tmp_path, FAR, fast_config()), "--sim", "--out", tmp_path / "runs")
    token, run_dir = token_of(proc)
    proc.send_signal(signal.SIGTERM)
    proc.communicate(timeout=30)
    try:
        connect(run_dir).close()
    except OSError:
        pass
    else:
        raise AssertionError("a finished scan still answers")
