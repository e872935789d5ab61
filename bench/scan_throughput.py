"""Points per second of a 2,000-point scan through the full stack (plan -> engine -> ESP and
PM100 drivers -> emulators on real ptys -> run store with an fsync per point), with zero
emulator latency and instant motion, beside its floor measured in the same run: the number
of protocol round trips the scan needed times the bare round-trip time of each device (a
pyserial write + readline of a typical request to the same emulator), plus the optical
bench's own time per reading.

Run: python bench/scan_throughput.py [--points 2000]
"""

from __future__ import annotations

import argparse
import math
import os
import tempfile
import time
from pathlib import Path

import serial
import tomllib

from gonio.config import parse_config
from gonio.plan import build_schedule, parse_plan
from gonio.runner import new_scan
from gonio.store import open_run
from sim.bench import build_power_source
from sim.devices.esp import EspEmulator
from sim.devices.motion import VirtualClock
from sim.devices.photodiode import ConstantPower
from sim.devices.pm100 import Pm100Emulator

ROOT = Path(__file__).resolve().parents[1]


def config_text() -> str:
    """sim-serial.toml with instant motion and a one-ray aperture rule ([sim.aperture] is
    the file's last table, so the added key lands in it)."""
    text = (ROOT / "examples" / "instruments" / "sim-serial.toml").read_text()
    text = text.replace("time_scale = 50.0", 'time_scale = "inf"')
    return text + "order = [0, 0]\n"


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


def bare_round_trip_s(emulator, request: bytes, n: int = 2000) -> float:
    """Mean seconds of one pyserial write + readline of `request` to a running emulator."""
    port = serial.Serial(emulator.start(), 115200, timeout=1.0)
    try:
        for _ in range(50):
            port.write(request)
            port.readline()
        t0 = time.perf_counter()
        for _ in range(n):
            port.write(request)
            if not port.readline():
                raise RuntimeError(f"no reply to {request!r}")
        return (time.perf_counter() - t0) / n
    finally:
        port.close()
        emulator.stop()


def physics_s(sim: dict, n: int = 300) -> float:
    """Mean seconds of one bench power evaluation at scan-like positions."""
    pos = {"sample": 20.0, "arm": 10.0, "azimuth": 0.0, "elevation": 0.0}
    source = build_power_source(sim, lambda: pos)
    t0 = time.perf_counter()
    for k in range(n):
        pos["arm"] = 10.0 + 340.0 * k / n
        source.power_w()
    return (time.perf_counter() - t0) / n


def fsync_s(folder: Path, n: int = 300) -> float:
    """Mean seconds to append and fsync one reading-sized line (what the store does)."""
    with open(folder / "fsync-probe", "ab") as fh:
        t0 = time.perf_counter()
        for _ in range(n):
            fh.write(b"x" * 400 + b"\n")
            fh.flush()
            os.fsync(fh.fileno())
        return (time.perf_counter() - t0) / n


def main() -> None:
    """Run the scan, measure the floors, print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=2000)
    args = parser.parse_args()
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
        sync_s = fsync_s(tmp)
    assert result.outcome.status == "completed" and len(r) == n, result.outcome
    loop_s = float(r["t_s"][-1] - r["t_s"][0]) * n / (n - 1)
    esp_s = bare_round_trip_s(EspEmulator(VirtualClock(math.inf), {1: {}}), b"1TP?\r")
    pm_s = bare_round_trip_s(Pm100Emulator(ConstantPower(1e-6)), b":READ?;:SENS:POW:RANG?\n")
    bench_s = physics_s(cfg.sim)
    floor_s = requests["esp"] * esp_s + requests["pm100"] * pm_s
    print(f"scan of {n} readings (sim-serial, instant motion, zero latency, fsync per point)")
    print(f"  round trips needed: esp {requests['esp']} ({requests['esp'] / n:.1f}/point), "
          f"pm100 {requests['pm100']} ({requests['pm100'] / n:.1f}/point)")
    print(f"  bare round trip: esp {esp_s * 1e3:.3f} ms, pm100 {pm_s * 1e3:.3f} ms; "
          f"bench physics {bench_s * 1e3:.3f} ms/reading; fsync {sync_s * 1e3:.3f} ms")
    print(f"{'':2}{'what':<46}{'seconds':>9}{'points/s':>10}")
    rows = [("full stack, measuring loop", loop_s),
            ("full stack, incl. start-up and plot-free finish", total_s),
            ("baseline: sum of bare protocol round trips", floor_s),
            ("baseline + bench physics", floor_s + n * bench_s),
            ("baseline + bench physics + an fsync per point", floor_s + n * (bench_s + sync_s))]
    for what, seconds in rows:
        print(f"  {what:<46}{seconds:>9.2f}{n / seconds:>10.0f}")
    floor_all = floor_s + n * (bench_s + sync_s)
    print(f"  full stack / (round trips + physics + fsync): {loop_s / floor_all:.2f}x; "
          f"engine and driver overhead {(loop_s - floor_all) / n * 1e3:.2f} ms/point")


if __name__ == "__main__":
    main()
