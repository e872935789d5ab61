"""The control channel of a real `gonio scan` process over its real Unix socket: status, pause
(readings stop growing, meta.json says paused), resume, abort (axes stopped on their way,
status aborted), a bad token refused with nothing done, the socket mode 0600 and removed when
the scan ends; the pause waits on the channel even with no terminal input."""

import json
import os
import signal
import stat
import subprocess
import sys
import time

from gonio_testkit import (
    ROOT,
    emulating,
    esp_arm_at_rest,
    fast_config,
    pointed,
    write_plan,
    write_toml,
)

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


def token_of(proc: subprocess.Popen) -> tuple[str, str]:
    """The token and run directory from the scan's `gonio: control token` stderr line."""
    for line in proc.stderr:
        if line.startswith("gonio: control token "):
            words = line.split()
            return words[3], words[6]
    raise AssertionError(f"no token line; stdout: {proc.stdout.read()}")


class Channel:
    """One connection to a run's control channel, several requests on it."""

    def __init__(self, run_dir: str):
        self.sock = connect(run_dir)
        self.lines = self.sock.makefile("rb")

    def ask(self, token: str, command: str) -> dict:
        self.sock.sendall(json.dumps({"token": token, "command": command}).encode() + b"\n")
        return json.loads(self.lines.readline())

    def close(self) -> None:
        self.lines.close()
        self.sock.close()


def until(predicate, timeout: float = 30.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = predicate()
        if value:
            return value
        time.sleep(0.01)
    raise AssertionError("condition not reached")


def test_status_pause_resume_abort_and_a_bad_token(tmp_path):
    proc = scan(write_plan(tmp_path, PLAN, fast_config(time_scale=8.0)), "--sim",
                "--out", tmp_path / "runs")
    token, run_dir = token_of(proc)
    assert stat.S_IMODE(os.stat(os.path.join(run_dir, SOCKET)).st_mode) == 0o600
    assert token not in "".join(p.read_text() for p in tmp_path.glob("runs/*/*.json"))
    channel = Channel(run_dir)
    try:
        first = channel.ask(token, "status")
        assert first["ok"] and first["state"] in ("starting", "running")
        first = until(lambda: (s := channel.ask(token, "status"))["state"] == "running" and s)
        assert first["planned"] > 20
        assert channel.ask("0" * 32, "pause") == {"ok": False, "error": "bad token"}
        assert channel.ask("", "status") == {"ok": False, "error": "bad token"}
        until(lambda: channel.ask(token, "status")["readings"] >= first["readings"] + 2)
        assert channel.ask(token, "status")["state"] == "running"  # the bad pause did nothing

        assert channel.ask(token, "pause")["state"] in ("pausing", "paused")
        paused = until(lambda: (s := channel.ask(token, "status"))["state"] == "paused" and s)
        time.sleep(0.4)  # no terminal input: the pause waits on the channel
        assert channel.ask(token, "status")["readings"] == paused["readings"]
        assert open_run(run_dir).meta["status"] == "paused"
        assert len(open_run(run_dir)) == paused["readings"]

        assert channel.ask(token, "resume")["state"] == "running"
        until(lambda: channel.ask(token, "status")["readings"] > paused["readings"])
        assert channel.ask(token, "resume") == {"ok": False, "error": "not paused (running)"}
        assert channel.ask(token, "abort")["state"] == "stopping"
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
    cfg = fast_config(time_scale=5.0)  # moves of tens of degrees take about a second
    with emulating(write_toml(tmp_path / "emulated.toml", cfg)) as endpoints:
        plan = write_plan(tmp_path, FAR, pointed(cfg, endpoints))
        proc = scan(plan, "--out", tmp_path / "runs")
        token, run_dir = token_of(proc)
        channel = Channel(run_dir)
        try:
            until(lambda: channel.ask(token, "status")["readings"] >= 1)
            time.sleep(0.3)  # into the next move
            assert channel.ask(token, "abort")["ok"]
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
