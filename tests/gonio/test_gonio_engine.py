"""The engine in-process on the emulated bench: a device error stops the run at once (not
retried) with the device's own words, and a double Ctrl-C during a long move stops the axis
where it is."""

import signal
import threading

import pytest
from gonio_testkit import fast_config, run_engine
from waiting import wait_until

from gonio.config import parse_config
from gonio.instrument import build_instrument
from gonio.plan import build_schedule, parse_plan
from gonio.run_control import PauseControl
from gonio.simulate import simulation
from gonio.store import RunWriter, open_run

ONE_MOVE = {"name": "one", "grid": [{"theta_i_deg": [0.0], "theta_o_deg": [40.0, 80.0]}]}


@pytest.fixture
def bench(tmp_path):
    """A running emulated sim-serial bench in real time; yields a function that runs a plan."""
    cfg = parse_config(fast_config(time_scale=1.0))
    with simulation(cfg) as sim, build_instrument(sim.config, sim.time_scale) as inst:
        def run(raw_plan, control=None):
            plan = parse_plan(raw_plan)
            sched = build_schedule(plan, cfg)
            writer = RunWriter.create(tmp_path, plan.name, None, None, raw_plan, cfg.raw, {})
            try:
                return run_engine(inst, plan, sched.readings, writer, control), writer
            finally:
                writer.close()
        yield sim.bench.emulators["esp"], run


def test_device_error_stops_at_once_with_the_devices_words(bench):
    esp, run = bench
    esp.axes[2].motion.limits = (6.0, 60.0)  # the controller's own limit, tighter than config
    outcome, writer = run(ONE_MOVE)
    assert outcome.status == "failed" and outcome.done == 1
    reason = open_run(writer.path).meta["reason"]
    assert reason.startswith("reading 1 (sample): moving the arm axis (esp.arm): esp: device "
                             "error 206: POSITIVE SOFTWARE LIMIT")
    assert "attempts" not in reason  # a device error is not retried


def test_second_ctrl_c_during_a_move_stops_the_axis(bench):
    esp, run = bench
    arm = esp.axes[2].motion
    pausing = threading.Event()

    def interrupt():
        wait_until(lambda: arm.position() >= 30.0, what="the move (6 -> 85 deg) under way")
        signal.raise_signal(signal.SIGINT)
        wait_until(pausing.is_set, what="the first Ctrl-C taken as a pause")
        signal.raise_signal(signal.SIGINT)

    far = {"name": "far", "grid": [{"theta_i_deg": [0.0], "theta_o_deg": [85.0]}]}
    threading.Thread(target=interrupt, daemon=True).start()
    outcome, writer = run(far, PauseControl(prompt=lambda: True,
                                            notify=lambda message: pausing.set()))
    assert outcome.status == "aborted" and outcome.done == 0
    # the stop decelerates (ST), it does not jump: the arm comes to rest after the run ends
    wait_until(lambda: not arm.is_moving(), what="the arm at rest")
    assert 30.0 < arm.position() < 80.0  # stopped well short of the target
    assert open_run(writer.path).meta["status"] == "aborted"


def test_the_arm_is_never_sent_through_the_source(bench):
    esp, run = bench
    arm = esp.axes[2].motion
    arm.limits = (-170.0, 170.0)
    arm.move_to(-30.0)  # left on the far side of the source by someone else
    wait_until(lambda: not arm.is_moving(), what="the arm at -30 deg")
    outcome, writer = run(ONE_MOVE)
    assert outcome.status == "failed" and outcome.done == 0
    assert "sweep through the source (-30 -> 40 deg); not moved" in open_run(writer.path
                                                                              ).meta["reason"]
    assert arm.position() == -30.0
