"""A register map's optional interlock status bit, emulator and driver each reading it from the
map on their own, over real Modbus TCP: while the unit's interlock input is open the drive
stops at once and refuses to move, the amplifier measures nothing, and the drivers raise
Interlocked; once it closes they run again."""

import math

import pytest
from modbus_testkit import DETECTOR_MAP, STAGE_MAP, endpoint_args  # noqa: I001 - own helpers

from drivers.base import Interlock, Interlocked
from drivers.modbus_detector import ModbusDetector
from drivers.modbus_stage import ModbusStage
from drivers.register_map import RegisterMap, RegisterMapError
from sim.devices.faults import InterlockInput, InterlockWindow
from sim.devices.modbus_detector import ModbusDetectorEmulator
from sim.devices.modbus_server import ModbusEmulatorServer
from sim.devices.modbus_stage import ModbusStageEmulator
from sim.devices.motion import VirtualClock
from sim.devices.photodiode import ConstantPower


def with_interlock(src, folder):
    """A copy of a shipped map with its commented-out interlock bit switched on."""
    out = folder / src.name
    out.write_text(src.read_text().replace("# interlock =", "interlock ="))
    return out


def test_an_open_interlock_stops_the_drive_and_blanks_the_amplifier(tmp_path):
    stage_map, detector_map = (with_interlock(m, tmp_path) for m in (STAGE_MAP, DETECTOR_MAP))
    now = [0.0]  # the interlock inputs' clock, set by the test
    window = InterlockWindow(start_s=10.0, duration_s=5.0)
    stage_emu = ModbusStageEmulator(VirtualClock(4.0), stage_map, (-95.0, 95.0), 20.0, 80.0,
                                    interlock=InterlockInput(window, lambda: now[0]))
    detector_emu = ModbusDetectorEmulator(ConstantPower(1e-5), detector_map, seed=3,
                                          interlock=InterlockInput(window, lambda: now[0]))
    server = ModbusEmulatorServer("tcp", {1: stage_emu, 2: detector_emu})
    server.start()
    kind, where, kw = endpoint_args(server)
    try:
        with ModbusStage(kind, where, 1, stage_map, name="drive", **kw) as stage, \
                ModbusDetector(kind, where, 2, detector_map, name="amp", **kw) as detector:
            assert isinstance(stage, Interlock) and stage.release_interlock() is None
            assert detector.read().power_w > 0
            stage.move_to(80.0)
            now[0] = 11.0  # the input opens mid-move
            with pytest.raises(Interlocked, match="drive: device error interlock"):
                stage.wait(10.0)
            stopped_at = stage.position()
            assert not stage_emu.axis.is_moving() and stopped_at < 80.0
            with pytest.raises(Interlocked):
                stage.move_to(0.0)
            assert stage.position() == stopped_at  # the start was not taken
            assert "interlock input open" in stage.release_interlock()
            measured = dict(detector_emu.model._visits)
            with pytest.raises(Interlocked):
                detector.read()
            assert detector_emu.model._visits == measured  # nothing measured while it is open
            now[0] = 15.0  # closed again
            assert stage.release_interlock() is None and detector.release_interlock() is None
            stage.move_to(0.0)
            assert math.isclose(stage.wait(10.0), 0.0, abs_tol=1e-3)
            assert detector.read().power_w > 0
    finally:
        server.stop()


def test_the_interlock_bit_must_be_a_bit_of_its_own(tmp_path):
    text = STAGE_MAP.read_text().replace("# interlock = 4", "interlock = 3")
    broken = tmp_path / "clash.toml"
    broken.write_text(text)
    with pytest.raises(RegisterMapError, match="status_bits.interlock = 3 is also 'fault'"):
        RegisterMap.load(broken)
    assert RegisterMap.load(with_interlock(STAGE_MAP, tmp_path)).status_bits["interlock"] == 4
    assert "interlock" not in RegisterMap.load(STAGE_MAP).status_bits  # optional
