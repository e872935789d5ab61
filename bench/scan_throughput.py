"""Points per second of a 2,000-point scan through the full stack, beside its floor.

Points per second of a 2,000-point scan through the full stack (plan -> engine -> ESP and
PM100 drivers -> emulators on real ptys -> run store with an fsync per point), with zero
emulator latency and instant motion, beside its floor: per point, serially, what the stack
cannot avoid, replayed at the scan's own positions and pace in one loop:

- round trips: the scan's per-point request lines (an ESP move and its motion-done + position
  poll, a PM100 reading), each written to a fresh emulator and its reply read with the system
  calls the serial transport makes (one os.write; select and os.read to the terminator), none
  of its checks; the requests the scan's emulators served, per device, times that device's
  mean exchange in the loop;
- bench physics: the optical bench evaluated at exactly the stage positions the scan
  recorded, after the same warm-up the emulators do before serving, the multiple-scattering
  tables walked on first use as the scan walked them (printed again with the tables walked:
  the per-reading cost of a longer scan);
- fsync: appending and fsyncing a line as long as the scan's, beside the run (the store
  overlaps each reading's fsync with the next point, so this part is a serial bound).

Method: the scan and its floor each run in a fresh process (cold caches on both sides),
alternately, `--repeats` times; each side's figure is the least of its repeats, so scheduler
noise (the machine's wake-up latency moves round trips and fsyncs severalfold between runs)
lands on both sides alike. Every repeat's ratio (its scan over the floor measured right
after it) is printed too, with their median.

Then the time per point with `gonio watch` following the store (its own process, polling the
run's files and checking each new line; no browser attached), against the same scan without
it just before and just after.

Run: python bench/scan_throughput.py [--points 2000] [--repeats 3]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import select
import subprocess
import sys
import tempfile
import time
import tomllib
import urllib.request
from pathlib import Path

import numpy as np
import serial

from gonio.config import parse_config
from gonio.plan import build_schedule, parse_plan
from gonio.runner import new_scan
from gonio.store import READINGS, open_run
from sim.bench import build_power_source
from sim.devices.esp import EspEmulator
from sim.devices.motion import VirtualClock
from sim.devices.photodiode import ConstantPower
from sim.devices.pm100 import Pm100Emulator

ROOT = Path(__file__).resolve().parents[1]
ROLES = ("sample", "arm", "azimuth", "elevation")
# what the engine sends per point with instant motion: the arm's move and its motion-done +
# position poll (ESP), and a reading with its range (PM100); each ends in its error status
ESP_LINES = (b"1PA%d;TB?\r", b"1MD?;1TP?;TB?\r")
PM100_LINES = (b":READ?;:SENS:POW:RANG?;:SYST:ERR?\n",)


def config_text() -> str:
    """sim-serial.toml with instant motion, the bench's default walks per multiple-scattering
    table build (the file asks 4x that for its demo fit) and a one-ray aperture rule (a
    [sim.aperture] table of its own at the end: the file has none)."""
    text = (ROOT / "examples" / "instruments" / "sim-serial.toml").read_text()
    text = text.replace("time_scale = 50.0", 'time_scale = "inf"')
    text = text.replace("\nms_walks = 262144 ", "\n# ms_walks = 262144 ")
    return text + "\n[sim.aperture]\norder = [0, 0]\n"


def plan_text(per_curve: int) -> str:
    """An in-plane plan: 5 incidences x 2 sides x per_curve outgoing angles."""
    return f"""name = "throughput"
instrument = "instrument.toml"
[[grid]]
side = ["reflection", "transmission"]
theta_i_deg = [5.0, 20.0, 35.0, 50.0, 65.0]
theta_o_deg = {{ start = -80.0, stop = 80.0, num = {per_curve} }}
skip_forbidden = true
"""


class BareClient:
    """A serial port opened as the transport opens it, exchanging lines with the system calls
    the transport makes: one os.write, then select and os.read until the reply's terminator."""

    def __init__(self, emulator, eol: bytes):
        self.emulator, self.eol = emulator, eol
        self.port = serial.serial_for_url(emulator.start(), baudrate=115200, timeout=1.0,
                                          write_timeout=1.0)
        self.fd = self.port.fileno()

    def exchange(self, line: bytes) -> None:
        """Write a line, read to the reply's terminator."""
        os.write(self.fd, line)
        reply = b""
        while not reply.endswith(self.eol):
            if not select.select([self.fd], [], [], 1.0)[0]:
                raise RuntimeError(f"no reply to {line!r}")
            reply += os.read(self.fd, 4096)

    def close(self) -> None:
        """Close the port, stop the emulator."""
        self.port.close()
        self.emulator.stop()


def _timed(seconds: dict[str, float], part: str, fn, *args) -> None:
    """Call fn(*args), adding its wall seconds to seconds[part] and the process's CPU seconds
    meanwhile to seconds[part + "_cpu"]."""
    t0, c0 = time.perf_counter(), time.process_time()
    fn(*args)
    seconds[part] += time.perf_counter() - t0
    seconds[part + "_cpu"] += time.process_time() - c0


def _append(fh, line: bytes) -> None:
    """What the run store does per reading: append the line and fsync it."""
    fh.write(line)
    os.fsync(fh.fileno())


def _floor(folder: Path) -> None:
    """The child that measures the floor: per point of the scan in folder (positions.npy,
    scan.json), serially, its ESP and PM100 round trips, its physics and an fsync of a line
    as long as the scan's; print as JSON the wall and CPU seconds of each part (the round
    trips per exchange) and of the physics again with the tables walked."""
    scan = json.loads((folder / "scan.json").read_text())
    sim = parse_config(tomllib.loads(config_text())).sim
    here = dict.fromkeys(ROLES, 0.0)
    source = build_power_source(sim, lambda: here)
    source.bench.warm_up()
    rows = np.load(folder / "positions.npy")
    esp = BareClient(EspEmulator(VirtualClock(math.inf), {1: {}}), b"\r\n")
    pm100 = BareClient(Pm100Emulator(ConstantPower(1e-6)), b"\n")
    line = b"x" * (scan["line_bytes"] - 1) + b"\n"
    seconds = dict.fromkeys((f"{part}{cpu}" for part in ("esp", "pm100", "physics", "fsync")
                             for cpu in ("", "_cpu")), 0.0)
    try:
        with open(folder / "fsync-probe", "ab", buffering=0) as fh:
            for _ in range(20):  # the transport's first exchanges, before the scan's loop
                esp.exchange(ESP_LINES[1])
                pm100.exchange(PM100_LINES[0])
            for k, row in enumerate(rows):
                here.update(zip(ROLES, map(float, row), strict=True))
                _timed(seconds, "esp", esp.exchange, ESP_LINES[0] % (10 + k % 2))
                _timed(seconds, "esp", esp.exchange, ESP_LINES[1])
                _timed(seconds, "physics", source.power_w)
                _timed(seconds, "pm100", pm100.exchange, PM100_LINES[0])
                _timed(seconds, "fsync", _append, fh, line)
    finally:
        esp.close()
        pm100.close()
    seconds["esp"] /= 2 * len(rows)
    seconds["pm100"] /= len(rows)
    seconds["warm"], seconds["warm_cpu"] = _physics_again(source, here, rows)
    print(json.dumps(seconds))


def _physics_again(source, here: dict[str, float], rows: np.ndarray) -> tuple[float, float]:
    """Wall and CPU seconds of the readings at rows' positions once more (tables walked)."""
    t0, c0 = time.perf_counter(), time.process_time()
    for row in rows:
        here.update(zip(ROLES, map(float, row), strict=True))
        source.power_w()
    return time.perf_counter() - t0, time.process_time() - c0


def cpu_s(pid: int) -> float:
    """CPU seconds (user + system) a process has used so far (/proc/PID/stat)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def per_point_s(folder: Path, watch: bool) -> tuple[float, float | None]:
    """Seconds per point of the scan's measuring loop (plan.toml in folder) and, with watch,
    the CPU seconds per point `gonio watch` spent following it (from before the first
    reading, the scan waiting for its URL; checked to have followed every reading)."""
    viewers: list = []

    def started(path: Path, token: str | None) -> None:
        viewer = subprocess.Popen([sys.executable, "-m", "gonio_cli", "watch", str(path)],
                                  stdout=subprocess.PIPE, text=True,
                                  env={**os.environ, "PYTHONPATH": str(ROOT)})
        url = viewer.stdout.readline().strip()
        viewers.extend((viewer, url, cpu_s(viewer.pid)))

    result = new_scan(folder / "plan.toml", sim=True, out=folder / "runs", progress=False,
                      started=started if watch else None)
    r = open_run(result.path).readings()
    assert result.outcome.status == "completed", result.outcome
    viewer_cpu = None
    if viewers:
        viewer, url, cpu0 = viewers
        time.sleep(0.5)  # one poll after the last line
        viewer_cpu = (cpu_s(viewer.pid) - cpu0) / len(r)
        with urllib.request.urlopen(url + "status.json") as reply:
            followed = json.load(reply)["readings"]
        viewer.terminate()
        viewer.wait()
        assert followed == len(r), f"gonio watch followed {followed} of {len(r)} readings"
    return float(r["t_s"][-1] - r["t_s"][0]) / (len(r) - 1), viewer_cpu


def load() -> str:
    """The 1, 5 and 15 minute load averages (figures on a shared machine move with them)."""
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def _stack(folder: Path) -> None:
    """The child that runs the scan (plan.toml in folder) through the full stack: print as
    JSON its measuring loop's and whole run's seconds, readings, requests served and line
    length; leave the stage positions it recorded (positions.npy) and scan.json for _floor."""
    t0 = time.perf_counter()
    result = new_scan(folder / "plan.toml", sim=True, out=folder / "runs", progress=False)
    total_s = time.perf_counter() - t0
    run = open_run(result.path)
    r = run.readings()
    assert result.outcome.status == "completed", result.outcome
    n = len(r)
    scan = {"loop_s": float(r["t_s"][-1] - r["t_s"][0]) * n / (n - 1), "total_s": total_s,
            "n": n, "requests": run.meta["sessions"][-1]["requests_served"],
            "line_bytes": round((result.path / READINGS).stat().st_size / n)}
    np.save(folder / "positions.npy", np.stack([r[f"{role}_deg"] for role in ROLES], axis=1))
    (folder / "scan.json").write_text(json.dumps(scan))
    print(json.dumps(scan))


def child(mode: str, folder: Path) -> dict:
    """Run this script as a fresh process in `mode` (--stack or --floor) on folder; what it
    printed last (JSON)."""
    out = subprocess.run([sys.executable, __file__, mode, str(folder)], capture_output=True,
                         text=True, check=True)
    return json.loads(out.stdout.splitlines()[-1])


def floor_parts(scan: dict, floor: dict) -> dict[str, float]:
    """The floor's parts for the whole scan, seconds: round trips (the requests served times
    the mean exchange), physics and fsync."""
    served = scan["requests"]
    return {"round trips": served["esp"] * floor["esp"] + served["pm100"] * floor["pm100"],
            "physics": floor["physics"], "fsync": floor["fsync"]}


def report(scans: list[dict], floors: list[dict], loads: tuple[str, str]) -> None:
    """Print the least scan beside the least floor, and each repeat's ratio."""
    totals = [sum(floor_parts(s, f).values()) for s, f in zip(scans, floors, strict=True)]
    best = min(range(len(floors)), key=totals.__getitem__)
    scan, floor = min(scans, key=lambda s: s["loop_s"]), floors[best]
    parts, n, served = floor_parts(scans[best], floor), scan["n"], scans[best]["requests"]
    print(f"scan of {n} readings (sim-serial, instant motion, zero latency, fsync per point); "
          f"load average {loads[0]} before, {loads[1]} after")
    print(f"  method: the scan and its floor (round trips, physics and fsync per point, "
          f"serially, at the scan's positions) each in a fresh process, alternately, "
          f"{len(scans)} times; the least of each")
    print(f"  round trips needed: esp {served['esp']} ({served['esp'] / n:.2f}/point), "
          f"pm100 {served['pm100']} ({served['pm100'] / n:.2f}/point)")
    print(f"  floor's parts: round trip esp {floor['esp'] * 1e3:.3f} ms, pm100 "
          f"{floor['pm100'] * 1e3:.3f} ms (the transport's system calls); bench physics at "
          f"the scan's positions {floor['physics'] / n * 1e3:.3f} ms/reading "
          f"({floor['physics_cpu'] / n * 1e3:.3f} ms of CPU; {floor['warm'] / n * 1e3:.3f} ms, "
          f"{floor['warm_cpu'] / n * 1e3:.3f} ms of CPU, again with its multiple-scattering "
          f"tables walked); fsync of a {scan['line_bytes']}-byte line "
          f"{floor['fsync'] / n * 1e3:.3f} ms")
    print(f"{'':2}{'what':<50}{'seconds':>9}{'points/s':>10}")
    rows = [("full stack, measuring loop", scan["loop_s"]),
            ("full stack, incl. start-up and plot-free finish",
             min(s["total_s"] for s in scans)),
            ("baseline: sum of bare protocol round trips", parts["round trips"]),
            ("baseline + bench physics", parts["round trips"] + parts["physics"]),
            ("baseline + bench physics + an fsync per point", totals[best])]
    for what, seconds in rows:
        print(f"  {what:<50}{seconds:>9.2f}{n / seconds:>10.0f}")
    for what, floor_s in (("round trips + physics", parts["round trips"] + parts["physics"]),
                          ("round trips + physics + fsync", totals[best])):
        print(f"  full stack / ({what}): {scan['loop_s'] / floor_s:.2f}x; beyond it "
              f"{(scan['loop_s'] - floor_s) / n * 1e3:.2f} ms/point")
    ratios = [s["loop_s"] / t for s, t in zip(scans, totals, strict=True)]
    print(f"  each repeat, full stack / (round trips + physics + fsync): "
          f"{', '.join(f'{x:.2f}x' for x in ratios)} (median {np.median(ratios):.2f}x)")
    print("  (the store fsyncs each reading while the engine moves on to the next one, so the "
          "full stack can beat the serial sum)")


def main() -> None:
    """Run the scan and its floor alternately, print the table, then the watch figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=2000)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--stack", type=Path, help=argparse.SUPPRESS)
    parser.add_argument("--floor", type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.stack or args.floor:
        (_stack if args.stack else _floor)(args.stack or args.floor)
        return
    load_before = load()
    cfg = parse_config(tomllib.loads(config_text()))
    per_curve = math.ceil(args.points / 10)
    while len(build_schedule(parse_plan(tomllib.loads(plan_text(per_curve))), cfg)
              ) < args.points:
        per_curve += 1
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        (tmp / "instrument.toml").write_text(config_text())
        (tmp / "plan.toml").write_text(plan_text(per_curve))
        scans, floors = [], []
        for _ in range(args.repeats):
            scans.append(child("--stack", tmp))
            floors.append(child("--floor", tmp))
        watched = [per_point_s(tmp, watch) for watch in (False, True, False)]
    report(scans, floors, (load_before, load()))
    (before, _), (with_watch, viewer_cpu), (after, _) = watched
    print(f"  per point, the same scan again: {before * 1e3:.3f} ms without gonio watch, "
          f"{with_watch * 1e3:.3f} ms with it following the store (no browser; its own CPU "
          f"{viewer_cpu * 1e3:.3f} ms/point), {after * 1e3:.3f} ms without "
          f"({with_watch / ((before + after) / 2) - 1:+.1%})")


if __name__ == "__main__":
    main()
