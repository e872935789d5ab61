"""The scan's protocol budget on real ptys: a moved ESP axis costs two round trips (its move,
then one motion-done-and-position poll), a reading one PM100 round trip; the position that
comes with "motion done" is exact or the reply is refused, never misread."""

import math

import numpy as np
import pytest
from garbling import reads_through_faults
from gonio_testkit import fast_config, run_engine

from drivers.esp import EspController
from gonio.config import parse_config
from gonio.instrument import build_instrument
from gonio.plan import MOTION_ROLES, build_schedule, parse_plan
from gonio.simulate import simulation
from gonio.store import RunWriter, open_run
from sim.devices.esp import EspEmulator
from sim.devices.faults import FaultInjector, FaultSpec
from sim.devices.motion import VirtualClock

PLAN = {"name": "budget", "grid": [{"side": ["reflection"], "theta_i_deg": [10.0, 30.0],
                                    "theta_o_deg": {"start": -60.0, "stop": 60.0, "num": 9},
                                    "skip_forbidden": True}]}


def moves(readings: np.ndarray, roles) -> int:
    """Axis moves the engine makes: every axis at the first reading, then each target change."""
    return sum(1 + int(np.count_nonzero(np.diff(readings[f"{role}_deg"]))) for role in roles)


def test_round_trips_per_point(tmp_path):
    raw = fast_config()
    raw["sim"]["sample"]["multiple_scattering"] = False  # a quick bench: this counts bytes
    cfg = parse_config(raw)
    plan = parse_plan(PLAN)
    sched = build_schedule(plan, cfg)
    with simulation(cfg) as sim, build_instrument(sim.config, sim.time_scale) as inst:
        writer = RunWriter.create(tmp_path, plan.name, None, None, PLAN, cfg.raw, {})
        before = sim.bench.request_counts()
        try:
            outcome = run_engine(inst, plan, sched.readings, writer)
        finally:
            writer.close()
        after = sim.bench.request_counts()
    n = len(sched.readings)
    assert outcome.status == "completed" and len(open_run(writer.path)) == n
    roles = [role for role in MOTION_ROLES if role in cfg.axes]
    # one TP? per axis to learn where it starts, then PA + (MD?;TP?) per move
    assert after["esp"] - before["esp"] == len(roles) + 2 * moves(sched.readings, roles)
    # the detector's settings once (wavelength, averaging, range), then one READ? per reading
    assert after["pm100"] - before["pm100"] == 3 + n


def test_wait_polls_motion_done_and_position_together():
    emu = EspEmulator(VirtualClock(20.0), {1: {"speed_deg_s": 20.0, "accel_deg_s2": 80.0}})
    emu.start()
    try:
        with EspController(emu.endpoint, timeout_s=0.5) as ctl:
            axis = ctl.axis(1)
            axis.move_to(30.0)  # 1.75 s of device time, about 90 ms here
            assert axis.wait(5.0) == 30.0
    finally:
        emu.stop()
    assert emu.server.handler_errors == []
    assert emu.received["MD?"] > 1  # it polled while the axis moved
    assert emu.received["TP?"] == emu.received["MD?"]  # no separate position query


@pytest.mark.parametrize("target", [7.12345, -0.5])
def test_a_garbled_done_and_position_reply_is_refused_not_misread(target):
    """A dropped byte anywhere in `1,7.12345,0, t, NO ERROR DETECTED`: a merged comma, a
    lost flag, a shortened number: each either breaks the reply's shape or hits only the
    timestamp; wait() never returns another position."""
    emu = EspEmulator(VirtualClock(math.inf), {1: {}})
    emu.start()
    try:
        with EspController(emu.endpoint, timeout_s=0.3, retries=0) as ctl:
            axis = ctl.axis(1)
            axis.move_to(target)
            emu.server.faults = FaultInjector(FaultSpec(drop_prob=1.0, seed=11))
            positions, refused = reads_through_faults(lambda: axis.wait(1.0), 150)
            # a drop in the timestamp, or a lost minus sign (no checksum on the ESP)
            assert all(p == target or (target < 0 and p == -target) for p in positions)
    finally:
        emu.stop()
    assert refused > 50
