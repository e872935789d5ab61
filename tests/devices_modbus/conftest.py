"""Fixtures: Modbus emulators (TCP on 127.0.0.1, RTU on a real pty) with drivers connected."""

import math
import os
import shutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import pytest
from modbus_testkit import (  # noqa: I001 - the test folder's own helpers
    DETECTOR_MAP,
    DETECTOR_UNIT,
    SECOND_STAGE_UNIT,
    STAGE_MAP,
    STAGE_UNIT,
    endpoint_args,
    with_word_order,
)

from drivers.modbus_detector import ModbusDetector
from drivers.modbus_stage import ModbusStage
from drivers.modbus_transport import ModbusTimeouts
from sim.devices.faults import FaultSpec
from sim.devices.modbus_detector import ModbusDetectorEmulator
from sim.devices.modbus_server import ModbusEmulatorServer
from sim.devices.modbus_stage import ModbusStageEmulator
from sim.devices.motion import VirtualClock
from sim.devices.photodiode import ConstantPower


@dataclass
class Rig:
    """Emulators on one endpoint and the drivers talking to them."""

    server: ModbusEmulatorServer
    stage_emu: ModbusStageEmulator
    second_emu: ModbusStageEmulator
    detector_emu: ModbusDetectorEmulator
    stage: ModbusStage
    second: ModbusStage
    detector: ModbusDetector
    stage_map: Path
    detector_map: Path
    open_drivers: Callable[[], tuple[ModbusStage, ModbusStage, ModbusDetector]]

    def step_aside(self) -> None:
        """Close the drivers, so that another master may take the port (a gonio link holds its
        serial port from its making to its close: drivers.port_lock)."""
        for drv in (self.stage, self.second, self.detector):
            drv.close()

    def step_back(self) -> None:
        """Open the drivers again once the other master is done."""
        self.stage, self.second, self.detector = self.open_drivers()


# every transport x word order the drivers and emulators must agree on
LINKS = [("tcp", "big"), ("tcp", "little"), ("rtu", "big"), ("rtu", "little")]


@pytest.fixture(params=LINKS, ids=[f"{t}-{o}" for t, o in LINKS])
def link(request):
    """(transport, word order) of one rig."""
    return request.param


@pytest.fixture(params=["big", "little"])
def word_order(request):
    """Word order of a rig's maps, for tests whose transport is fixed."""
    return request.param


@pytest.fixture
def rig(tmp_path):
    """make(transport, word_order, time_scale, stage_faults, server_faults, source, reply_s,
    read_retries, detector, clock) -> Rig (the stages on `clock` if given, else on a
    VirtualClock at time_scale); everything is stopped after the test."""
    made = []

    def make(transport="tcp", word_order="big", time_scale=math.inf, stage_faults=None,
             server_faults=None, detector_faults=None, source=None, reply_s=0.2,
             read_retries=2, detector=None, clock=None):
        stage_map = with_word_order(STAGE_MAP, word_order, tmp_path)
        detector_map = with_word_order(DETECTOR_MAP, word_order, tmp_path)
        clock = clock or VirtualClock(time_scale)
        stage_emu = ModbusStageEmulator(clock, stage_map, (-95.0, 95.0), 20.0, 80.0,
                                        faults=stage_faults and FaultSpec(**stage_faults))
        second_emu = ModbusStageEmulator(clock, stage_map, (-170.0, 170.0), 30.0, 120.0)
        detector_emu = ModbusDetectorEmulator(
            source or ConstantPower(1e-5), detector_map,
            faults=detector_faults and FaultSpec(**detector_faults), seed=3, detector=detector)
        server = ModbusEmulatorServer(
            transport, {STAGE_UNIT: stage_emu, DETECTOR_UNIT: detector_emu,
                        SECOND_STAGE_UNIT: second_emu},
            faults=server_faults and FaultSpec(**server_faults))
        server.start()
        kind, where, kw = endpoint_args(server)
        timeouts = ModbusTimeouts(reply_s=reply_s)
        common = dict(timeouts=timeouts, read_retries=read_retries, **kw)

        def open_drivers() -> tuple[ModbusStage, ModbusStage, ModbusDetector]:
            return (ModbusStage(kind, where, STAGE_UNIT, stage_map, name="sample", **common),
                    ModbusStage(kind, where, SECOND_STAGE_UNIT, stage_map, name="arm", **common),
                    ModbusDetector(kind, where, DETECTOR_UNIT, detector_map, name="det",
                                   **common))

        rig = Rig(server, stage_emu, second_emu, detector_emu, *open_drivers(), stage_map,
                  detector_map, open_drivers)
        made.append(rig)
        return rig

    yield make
    for r in made:
        for drv in (r.stage, r.second, r.detector):
            drv.close()
        r.server.stop()


@pytest.fixture(scope="module")
def mbpoll():
    """Path of mbpoll: a failure in CI (it must be installed there), a skip elsewhere."""
    path = shutil.which("mbpoll")
    if path is None:
        if os.environ.get("CI") == "true":
            pytest.fail("mbpoll is not installed but CI=true (.ci/run installs it)")
        pytest.skip("mbpoll not installed (Debian: apt-get install mbpoll)")
    return path
