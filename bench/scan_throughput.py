"""Points per second of a 2,000-point scan through the full stack, beside its floor.

Points per second of a 2,000-point scan through the full stack (plan -> engine -> ESP and
PM100 drivers -> emulators on real ptys -> run store with an fsync per point), with zero
emulator latency and instant motion, beside its floor measured in the same run:

- round trips: the requests the emulators served during the scan, per device, times the
  bare round trip of that device (a plain pyserial client writing the scan's own per-point
  request lines to a fresh emulator and reading each reply to its terminator);
- bench physics: the optical bench evaluated at exactly the stage positions the scan
  recorded, in the scan's order, in a fresh process (cold caches, after the same warm-up the
  emulators do before serving), so the multiple-scattering tables the scan walked on first
  use are counted as they were paid in the scan (printed again with the tables walked: the
  per-reading cost of a longer scan);
- fsync: appending and fsyncing as many lines, as long as the scan's, beside the run (the
  store overlaps each reading's fsync with the next point, so this part is a serial bound).

Then the time per point with `gonio watch` following the store (its own process, polling the
run's files and checking each new line; no browser attached), against the same scan without
it just before and just after.

Run: python bench/scan_throughput.py [--points 2000]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path

import numpy as np
import serial
import tomllib

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
ESP_LINES = (b"1PA{target};TB?\r", b"1MD?;1TP?;TB?\r")
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


def bare_round_trip_s(emulator, lines: tuple[bytes, ...], eol: bytes, n: int = 2000) -> float:
    """Mean seconds of one exchange of a plain pyserial client with a running emulator: write
    a line, read until the reply's terminator; the lines are sent in turn ({target} becomes
    an alternating move target)."""
    port = serial.Serial(emulator.start(), 115200, timeout=1.0)

    def exchange(k: int) -> None:
        port.write(lines[k % len(lines)].replace(b"{target}", b"%d" % (10 + k // len(lines) % 2)))
        reply = b""
        while not reply.endswith(eol):
            chunk = port.read(max(1, port.in_waiting))
            if not chunk:
                raise RuntimeError(f"no reply to {lines[k % len(lines)]!r}")
            reply += chunk

    try:
        for k in range(50):
            exchange(k)
        t0 = time.perf_counter()
        for k in range(n):
            exchange(k)
        return (time.perf_counter() - t0) / n
    finally:
        port.close()
        emulator.stop()


def physics_replay_s(positions_file: Path) -> tuple[float, float, float, float]:
    """Seconds (wall, CPU) the bench takes for the readings at the stage positions in
    positions_file (rows of ROLES), in order, after the emulators' warm-up: run in a fresh
    process, so no table the scan walked is warm here; then (wall, CPU) of the same readings
    again, the tables walked. CPU time (all the process's threads) shows how much of the wall
    time a loaded machine added."""
    out = subprocess.run([sys.executable, __file__, "--replay-physics", str(positions_file)],
                         capture_output=True, text=True, check=True)
    wall, cpu, warm_wall, warm_cpu = map(float, out.stdout.split()[-4:])
    return wall, cpu, warm_wall, warm_cpu


def _replay_physics(positions_file: Path) -> None:
    """The child of physics_replay_s: print the wall and CPU seconds of the evaluations, first
    as the scan paid them, then again with the tables walked."""
    sim = parse_config(tomllib.loads(config_text())).sim
    here = dict.fromkeys(ROLES, 0.0)
    source = build_power_source(sim, lambda: here)
    source.bench.warm_up()
    rows = np.load(positions_file)
    for _ in range(2):
        wall = cpu = 0.0
        for row in rows:
            here.update(zip(ROLES, map(float, row), strict=True))
            t0, c0 = time.perf_counter(), time.process_time()
            source.power_w()
            wall += time.perf_counter() - t0
            cpu += time.process_time() - c0
        print(wall, cpu)


def fsync_s(folder: Path, n: int, line_bytes: int) -> float:
    """Seconds to append and fsync n lines of line_bytes each (what the store does per
    reading, without the JSON encoding)."""
    with open(folder / "fsync-probe", "ab") as fh:
        t0 = time.perf_counter()
        for _ in range(n):
            fh.write(b"x" * (line_bytes - 1) + b"\n")
            fh.flush()
            os.fsync(fh.fileno())
        return time.perf_counter() - t0


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


def main() -> None:
    """Run the scan, measure the floors, print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=2000)
    parser.add_argument("--replay-physics", type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.replay_physics:
        _replay_physics(args.replay_physics)
        return
    load_before = load()
    cfg = parse_config(tomllib.loads(config_text()))
    per_curve = math.ceil(args.points / 10)
    while (n := len(build_schedule(parse_plan(tomllib.loads(plan_text(per_curve))), cfg))
           ) < args.points:
        per_curve += 1
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        (tmp / "instrument.toml").write_text(config_text())
        (tmp / "plan.toml").write_text(plan_text(per_curve))
        t0 = time.perf_counter()
        result = new_scan(tmp / "plan.toml", sim=True, out=tmp / "runs", progress=False)
        total_s = time.perf_counter() - t0
        run = open_run(result.path)
        r = run.readings()
        requests = run.meta["sessions"][-1]["requests_served"]
        line_bytes = round((result.path / READINGS).stat().st_size / max(len(r), 1))
        sync_s = fsync_s(tmp, n, line_bytes)
        np.save(tmp / "positions.npy", np.stack([r[f"{role}_deg"] for role in ROLES], axis=1))
        bench_s, bench_cpu_s, warm_s, warm_cpu_s = physics_replay_s(tmp / "positions.npy")
        watched = [per_point_s(tmp, watch) for watch in (False, True, False)]
    assert result.outcome.status == "completed" and len(r) == n, result.outcome
    loop_s = float(r["t_s"][-1] - r["t_s"][0]) * n / (n - 1)
    esp_s = bare_round_trip_s(EspEmulator(VirtualClock(math.inf), {1: {}}), ESP_LINES, b"\r\n")
    pm_s = bare_round_trip_s(Pm100Emulator(ConstantPower(1e-6)), PM100_LINES, b"\n")
    floor_s = requests["esp"] * esp_s + requests["pm100"] * pm_s
    print(f"scan of {n} readings (sim-serial, instant motion, zero latency, fsync per point); "
          f"load average {load_before} before, {load()} after")
    print(f"  round trips needed: esp {requests['esp']} ({requests['esp'] / n:.2f}/point), "
          f"pm100 {requests['pm100']} ({requests['pm100'] / n:.2f}/point)")
    print(f"  bare round trip: esp {esp_s * 1e3:.3f} ms, pm100 {pm_s * 1e3:.3f} ms; "
          f"bench physics at the scan's positions {bench_s / n * 1e3:.3f} ms/reading "
          f"({bench_cpu_s / n * 1e3:.3f} ms of CPU; {warm_s / n * 1e3:.3f} ms, "
          f"{warm_cpu_s / n * 1e3:.3f} ms of CPU, again with its multiple-scattering tables "
          f"walked); "
          f"fsync of a {line_bytes}-byte line {sync_s / n * 1e3:.3f} ms")
    print(f"{'':2}{'what':<50}{'seconds':>9}{'points/s':>10}")
    floor_all = floor_s + bench_s + sync_s
    rows = [("full stack, measuring loop", loop_s),
            ("full stack, incl. start-up and plot-free finish", total_s),
            ("baseline: sum of bare protocol round trips", floor_s),
            ("baseline + bench physics", floor_s + bench_s),
            ("baseline + bench physics + an fsync per point", floor_all)]
    for what, seconds in rows:
        print(f"  {what:<50}{seconds:>9.2f}{n / seconds:>10.0f}")
    for what, floor in (("round trips + physics", floor_s + bench_s),
                        ("round trips + physics + fsync", floor_all)):
        print(f"  full stack / ({what}): {loop_s / floor:.2f}x; beyond it "
              f"{(loop_s - floor) / n * 1e3:.2f} ms/point")
    print("  (the store fsyncs each reading while the engine moves on to the next one, so the "
          "full stack can beat the serial sum)")
    (before, _), (with_watch, viewer_cpu), (after, _) = watched
    print(f"  per point, the same scan again: {before * 1e3:.3f} ms without gonio watch, "
          f"{with_watch * 1e3:.3f} ms with it following the store (no browser; its own CPU "
          f"{viewer_cpu * 1e3:.3f} ms/point), {after * 1e3:.3f} ms without "
          f"({with_watch / ((before + after) / 2) - 1:+.1%})")


if __name__ == "__main__":
    main()
