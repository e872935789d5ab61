"""Two Zaber devices daisy-chained on one serial port, each with a ZaberController of its own
(what a config with two `zaber` devices on one port opens), against the chain emulator on a
real pty: one line for both (one hold, one connection, one sync query), both axes moved in
turn while the other's move runs, errors naming the device asked, a controller asking for
other line settings refused naming both, and the port held until the last controller closes
(then another process can hold it)."""

import os
import subprocess
import sys
from pathlib import Path

import pytest
from ticking_clock import TickingClock

from drivers.base import ProtocolError
from drivers.port_lock import PortInUse, hold
from drivers.zaber import ZaberController
from sim.devices.faults import FaultInjector, FaultSpec
from sim.devices.motion import VirtualClock, profile_times
from sim.devices.zaber import ZaberEmulator

ROOT = Path(__file__).resolve().parents[2]
UNIT = 0.015 / 64  # X-RSW60A microstep at the default resolution, degrees
STAGE = {"limits_deg": (-170.0, 170.0), "speed_deg_s": 20.0, "accel_deg_s2": 80.0}
# another process holding the port: prints "held", or "refused: <the PortInUse message>"
HOLDER = """
import sys
from drivers.port_lock import PortInUse, hold
try:
    hold(sys.argv[1], "other").release()
except PortInUse as exc:
    print("refused:", exc)
else:
    print("held")
"""


@pytest.fixture
def chain(opened):
    """make(clock) -> (emulator, sample controller at address 1, arm controller at 2): two
    single-axis devices on one emulated chain, both controllers on its one pty."""

    def make(clock=None):
        emu = ZaberEmulator(clock or VirtualClock(float("inf")), {(1, 1): STAGE, (2, 1): STAGE})
        emu.start()
        opened.append(emu)
        controllers = []
        for name, address in (("sample", 1), ("arm", 2)):
            controllers.append(ZaberController(emu.endpoint, name=name, address=address,
                                               timeout_s=0.3))
            opened.append(controllers[-1])
        return emu, *controllers

    return make


def another_process_holding(port: str) -> str:
    """What another process trying to hold the port says."""
    done = subprocess.run([sys.executable, "-c", HOLDER, port], capture_output=True, text=True,
                          env={**os.environ, "PYTHONPATH": str(ROOT)}, timeout=60)
    assert done.returncode == 0, done.stderr
    return done.stdout.strip()


def test_two_controllers_share_the_chains_one_line(chain):
    emu, sample, arm = chain()
    assert sample.transport is arm.transport  # one hold, one connection
    # one sync query, the first device's: its checksum is -(byte sum of "1 0 99", 275) mod 256
    assert arm.transport.sync.line == "/1 0 99:ED"
    assert sample.identity() == {"device_id": "50001", "serial": "120001", "firmware": "7.38",
                                 "address": "1"}
    assert arm.identity() == {"device_id": "50001", "serial": "120002", "firmware": "7.38",
                              "address": "2"}
    assert [emu.devices[n].settings["comm.checksum"] for n in (1, 2)] == [1, 1]


def test_both_axes_move_in_turn_while_the_other_runs(chain):
    emu, sample_ctl, arm_ctl = chain(TickingClock(0.01))  # each read: 10 virtual ms
    sample, arm = sample_ctl.axis(1, "sample"), arm_ctl.axis(1, "arm")
    assert (sample.name, arm.name) == ("sample", "arm")
    move_s = sum(profile_times(40.0, 20.0, 80.0))  # 2.25 virtual s a 40 deg move
    for step, (to_sample, to_arm) in enumerate([(40.0, -40.0), (0.0, 0.0), (-40.0, 40.0)]):
        sample.move_to(to_sample)
        arm.move_to(to_arm)
        assert sample.is_moving() and arm.is_moving()  # both under way at once
        assert sample.wait(60.0) == pytest.approx(to_sample, abs=UNIT)
        assert arm.position() == pytest.approx(emu.axis_position_deg((2, 1)), abs=UNIT)
        assert arm.wait(60.0) == pytest.approx(to_arm, abs=UNIT)
        assert emu.received["move abs"] == 2 * (step + 1)
    assert emu.clock.now() > 3 * move_s
    assert sample.line_counts() == arm.line_counts() == {"resyncs": 0, "unsolicited": 0}


def test_an_error_names_the_device_that_was_asked(chain):
    emu, sample_ctl, arm_ctl = chain()
    sample, arm = sample_ctl.axis(1), arm_ctl.axis(1)
    emu.server.faults = FaultInjector(FaultSpec(corrupt_prob=1.0, seed=3))
    with pytest.raises(ProtocolError, match=r"^arm: garbled reply to get pos \(device 2 axis "):
        arm.position()
    with pytest.raises(ProtocolError, match=r"^sample: garbled reply to get pos \(device 1 "):
        sample.position()
    emu.server.faults = FaultInjector(None)
    arm.move_to(12.5)
    assert arm.wait(10.0) == pytest.approx(12.5, abs=UNIT)


def test_other_line_settings_on_the_chains_port_are_refused_naming_both(chain):
    emu, sample, arm = chain()
    with pytest.raises(ValueError) as refused:
        ZaberController(emu.endpoint, name="elevation", address=3, baudrate=9600,
                        parity="even", timeout_s=0.3)
    assert str(refused.value) == (
        f"elevation: {emu.endpoint} is the line of sample, opened with baudrate 115200, parity "
        "'none'; elevation gives baudrate 9600, parity 'even' (devices on one line must agree "
        "on its settings)")
    arm.close()
    sample.close()  # the refused controller took no share: the port is free
    assert another_process_holding(emu.endpoint) == "held"


def test_the_port_is_held_until_the_last_controller_closes(chain):
    emu, sample, arm = chain()
    port = emu.endpoint
    sample.close()
    sample.close()  # idempotent: the arm's share is not given back twice
    assert arm.axis(1).position() == pytest.approx(0.0, abs=UNIT)  # the arm still answers
    arm.axis(1).move_to(-20.0)
    assert emu.axis_position_deg((2, 1)) == pytest.approx(-20.0, abs=UNIT)
    with pytest.raises(PortInUse):
        hold(port, "elevation")
    assert another_process_holding(port).startswith(
        f"refused: other: {port} is in use by process {os.getpid()} (")
    arm.close()
    assert another_process_holding(port) == "held"
