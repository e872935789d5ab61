"""Helpers for the gonio tests (a plain module, not a conftest, so its name is unique):
example configs made fast (instant motion, cheap aperture integral), a small TOML writer,
running the real `gonio` CLI (and `gonio emulate`) in a subprocess, the emulators `gonio
emulate` serves in this process (to watch their motion), a scan's control channel, and a Ctrl-C
stand-in that aborts a scan after some points."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import tomllib
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from waiting import wait_until

from gonio.engine import Engine, Outcome
from gonio.events import EventBus
from gonio.recorder import RunRecorder
from gonio.run_control import TERMINAL, PauseControl
from sim.emulate import EmulatedBench

ROOT = Path(__file__).resolve().parents[2]
#: round trips over which an arm at rest must stay put (or a paused run unchanged)
REST_CHECKS = 30
EXAMPLES = ROOT / "examples"


def toml_value(value) -> str:
    """One TOML value (numbers, strings, booleans, arrays, inline tables)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return repr(value) if value == value and abs(value) != float("inf") else (
            "nan" if value != value else ("inf" if value > 0 else "-inf"))
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, list):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{json.dumps(k)} = {toml_value(v)}" for k, v in value.items()) + "}"
    raise TypeError(f"cannot write {value!r} as TOML")


def dump_toml(data: dict, prefix: str = "", inline_dicts: bool = False) -> str:
    """A dict as TOML text: dicts become [tables], lists of dicts [[arrays of tables]]
    (whose own dict values are written inline)."""
    lines, tables = [], []
    for key, value in data.items():
        is_table = isinstance(value, dict) and not inline_dicts
        is_array = isinstance(value, list) and value and all(isinstance(v, dict) for v in value)
        if is_table or is_array:
            tables.append((key, value))
        else:
            lines.append(f"{json.dumps(key)} = {toml_value(value)}")
    text = "".join(line + "\n" for line in lines)
    for key, value in tables:
        name = f"{prefix}{json.dumps(key)}"
        if isinstance(value, list):
            for item in value:
                text += f"\n[[{name}]]\n" + dump_toml(item, name + ".", inline_dicts=True)
        else:
            text += f"\n[{name}]\n" + dump_toml(value, name + ".")
    return text


def load_example(name: str) -> dict:
    """An example instrument config as a dict, register maps made absolute."""
    cfg = tomllib.loads((EXAMPLES / "instruments" / f"{name}.toml").read_text())
    for dev in cfg["devices"].values():
        if "register_map" in dev:
            dev["register_map"] = str((EXAMPLES / "instruments" / dev["register_map"]).resolve())
    return cfg


def fast_config(name: str = "sim-serial", *, elevation: bool = False, time_scale="inf",
                faults: dict | None = None, **device_overrides) -> dict:
    """An example config with instant motion, a cheap aperture rule and optional extras."""
    cfg = load_example(name)
    cfg["sim"]["time_scale"] = time_scale
    cfg["sim"].setdefault("aperture", {})["order"] = [0, 0]  # one node: the centre ray
    if elevation:
        controller = next((d for d in ("esp", "zaber") if d in cfg["devices"]), None)
        if controller:
            cfg["axes"]["elevation"] = {"device": controller, "axis": 3,
                                        "limits_deg": [-60.0, 60.0], "speed_deg_s": 10.0,
                                        "accel_deg_s2": 40.0, "settle_s": 0.01}
        else:
            drive = dict(cfg["devices"]["arm_drive"], unit=4)
            cfg["devices"]["elevation_drive"] = drive
            cfg["axes"]["elevation"] = {"device": "elevation_drive",
                                        "limits_deg": [-60.0, 60.0], "speed_deg_s": 10.0,
                                        "accel_deg_s2": 40.0, "settle_s": 0.01}
    for dev, changes in device_overrides.items():
        cfg["devices"][dev].update(changes)
    if faults:
        cfg["sim"]["faults"] = faults
    return cfg


def write_toml(path: Path, data: dict) -> Path:
    """Write a dict as a TOML file and check it reads back the same."""
    text = dump_toml(data)
    assert tomllib.loads(text) == data, text
    path.write_text(text)
    return path


def gonio_cli(*args, timeout: float = 120.0, input: str | None = None, cwd=None
              ) -> subprocess.CompletedProcess:
    """Run `python -m gonio_cli ARGS` and return the completed process (text output)."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run([sys.executable, "-m", "gonio_cli", *map(str, args)],
                          capture_output=True, text=True, timeout=timeout, input=input,
                          cwd=cwd or ROOT, env=env)


def start_gonio(*args, stdin=subprocess.DEVNULL) -> subprocess.Popen:
    """Start `python -m gonio_cli ARGS` in the background (text output on pipes), SIGHUP at
    its default as from a terminal: a test run under nohup would otherwise hand the child an
    ignored SIGHUP, which gonio keeps ignored."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.Popen([sys.executable, "-m", "gonio_cli", *map(str, args)], stdin=stdin,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
                            preexec_fn=_hangup_by_default)


def _hangup_by_default() -> None:
    signal.signal(signal.SIGHUP, signal.SIG_DFL)


def wait_for_lines(runs, n: int, proc: subprocess.Popen, timeout: float = 60.0) -> None:
    """Until a run under `runs` holds n readings lines (or the process ended)."""
    def reached() -> bool:
        found = list(runs.glob("*/readings.jsonl"))
        return proc.poll() is not None or bool(found) and (
            found[0].read_bytes().count(b"\n") >= n)

    wait_until(reached, timeout, "the scan's progress")


def run_dir_of(proc: subprocess.CompletedProcess) -> Path:
    """The run directory: the last line of a scan's stdout."""
    lines = proc.stdout.strip().splitlines()
    assert lines, f"no stdout; stderr:\n{proc.stderr}"
    return Path(lines[-1])


def completed_unretried(proc: subprocess.CompletedProcess):
    """The run a `gonio scan` made, checked whole: exit 0, status completed, every planned
    reading stored and none of them retried."""
    from gonio.store import open_run

    assert proc.returncode == 0, proc.stderr
    run = open_run(run_dir_of(proc))
    assert run.meta["status"] == "completed"
    readings = run.readings()
    assert len(readings) == run.meta["planned"]
    assert not any("retried" in flags.split(",") for flags in readings["flags"])
    return run


def scan_messages(stderr: str) -> list[str]:
    """A scan's stderr lines, less the control channel's token line (gonio.control)."""
    return [ln for ln in stderr.splitlines()
            if ln.strip() and not ln.startswith("gonio: control token ")]


def one_line_error(stderr: str) -> str:
    """Assert stderr is exactly one `gonio VERB: error: ...` line without a traceback."""
    lines = [ln for ln in stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, stderr
    assert "Traceback" not in stderr
    assert re.match(r"gonio \w+: error: \S", lines[0]), lines[0]
    return lines[0]


def rewrite_run_files(run_dir: Path, plan: dict | None = None, config: dict | None = None
                      ) -> None:
    """Replace a run's plan.json and/or config.json and record their digests in meta.json,
    as if the run had been made with them (a changed file is otherwise damage)."""
    from gonio.store import META, digests

    for name, data in (("plan.json", plan), ("config.json", config)):
        if data is not None:
            (run_dir / name).write_text(json.dumps(data))
    meta = json.loads((run_dir / META).read_text())
    meta["digests"] = digests(json.loads((run_dir / "plan.json").read_text()),
                              json.loads((run_dir / "config.json").read_text()))
    (run_dir / META).write_text(json.dumps(meta))


def write_plan(folder: Path, plan: dict, config: dict | None = None, name: str = "plan") -> Path:
    """Write a plan dict (and its instrument config, named by the plan) into folder."""
    plan = dict(plan)
    if config is not None:
        write_toml(folder / f"{name}-instrument.toml", config)
        plan["instrument"] = f"{name}-instrument.toml"
    return write_toml(folder / f"{name}.toml", plan)


def run_engine(inst, plan, readings, writer, control: PauseControl | None = None) -> Outcome:
    """Run an engine over the readings a writer has not stored, into that writer."""
    return Engine(inst, plan, readings, writer.todo(len(readings)),
                  EventBus([RunRecorder(writer)]), stored=writer.stored, control=control).run()


class AbortAfter(PauseControl):
    """A Ctrl-C answered with "abort" once `points` readings are taken: leaves a run to resume."""

    def __init__(self, points: int = 0) -> None:
        super().__init__(prompt=lambda: False, notify=lambda _message: None)
        self.left = points

    def checkpoint(self, on_pause, on_resume) -> None:
        if self.left <= 0:
            self.request_pause(TERMINAL)
        self.left -= 1
        super().checkpoint(on_pause, on_resume)


@contextmanager
def emulating(config_path: Path, *options: str) -> Iterator[dict[str, tuple[str, str]]]:
    """`gonio emulate CFG [OPTIONS]` in its own process; yields {device: (protocol, endpoint)}."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen([sys.executable, "-m", "gonio_cli", "emulate", str(config_path),
                             *options],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        endpoints = {}
        for _ in tomllib.loads(config_path.read_text())["devices"]:
            name, protocol, endpoint = proc.stdout.readline().split()
            endpoints[name] = (protocol, endpoint)
        yield endpoints
    finally:
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=20)
        assert proc.returncode == 0, err


@contextmanager
def serving(config_path: Path) -> Iterator[tuple[dict[str, tuple[str, str]], EmulatedBench]]:
    """What `gonio emulate CFG` serves (gonio.simulate.serve), in this process; yields the
    endpoints as `emulating` does and the bench, whose emulated axes a test may watch."""
    from gonio.config import load_config
    from gonio.simulate import serve

    with serve(load_config(config_path)) as bench:
        yield {name: (e.protocol, e.endpoint) for name, e in bench.endpoints.items()}, bench


def arm_on_its_way(bench: EmulatedBench, target_deg: float, past_deg: float) -> None:
    """Until the emulated ESP arm (axis 2) moves toward target_deg and has passed past_deg (a
    move under way, watched in the emulator, not over the port the scan holds)."""
    arm = bench.emulators["esp"].axes[2].motion
    wait_until(lambda: arm.is_moving() and arm.target() == target_deg
               and arm.position() >= past_deg, what=f"the arm past {past_deg:g} deg on its "
               f"way to {target_deg:g} deg")


def pointed(cfg: dict, endpoints: dict[str, tuple[str, str]]) -> dict:
    """What a user does by hand: a config with the endpoints `gonio emulate` printed."""
    cfg = {**cfg, "devices": {n: dict(d) for n, d in cfg["devices"].items()}}
    for name, (protocol, endpoint) in endpoints.items():
        dev = cfg["devices"][name]
        if protocol == "modbus-tcp":
            host, port = endpoint.rsplit(":", 1)
            dev.update(host=host, tcp_port=int(port))
        else:  # a pty path for a port, a VISA resource string for a resource
            dev["resource" if "resource" in dev else "port"] = endpoint
    return cfg


def esp_arm_at_rest(port_path: str, timeout_s: float = 5.0) -> float:
    """The ESP arm's (axis 2) position once a stop has brought it to rest: waits for MD? to
    say done (the stop was sent; the arm decelerates), then checks it stays put over
    REST_CHECKS more round trips."""
    import serial

    with serial.Serial(port_path, 19200, timeout=2) as port:
        def ask(command: str) -> str:
            port.write(command.encode() + b"\r")
            return port.readline().decode().strip()

        wait_until(lambda: ask("2MD?") == "1", timeout_s, "the arm at rest")
        first = float(ask("2TP"))
        for _ in range(REST_CHECKS):
            assert ask("2MD?;2TP") == f"1,{first:.5f}"  # at rest, unmoved
        return first


def token_of(proc: subprocess.Popen) -> tuple[str, str]:
    """The token and run directory from a scan's `gonio: control token` stderr line (the
    lines before it are read and dropped)."""
    for line in proc.stderr:
        if line.startswith("gonio: control token "):
            words = line.split()
            return words[3], words[6]
    raise AssertionError(f"no token line; stdout: {proc.stdout.read()}")


class Channel:
    """One connection to a run's control channel (gonio.control), several requests on it."""

    def __init__(self, run_dir: str | Path, token: str):
        from gonio.control import connect

        self.token = token
        self.sock = connect(run_dir)
        self.lines = self.sock.makefile("rb")

    def ask(self, command: str, token: str | None = None) -> dict:
        """The reply to one command, with the session's token unless another is given."""
        request = {"token": self.token if token is None else token, "command": command}
        self.sock.sendall(json.dumps(request).encode() + b"\n")
        return json.loads(self.lines.readline())

    def stays_paused(self, readings: int) -> None:
        """The run answers paused with `readings` stored over REST_CHECKS round trips: the
        scan's channel thread serves them while nothing is measured."""
        for _ in range(REST_CHECKS):
            status = self.ask("status")
            assert (status["state"], status["readings"]) == ("paused", readings), status

    def close(self) -> None:
        """Close the connection."""
        self.lines.close()
        self.sock.close()
