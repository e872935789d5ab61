"""A pty whose emulator stops mid-session: every failure reaches the caller as a DriverError
(SerialPortError naming device, port and what failed), never termios.error or OSError."""

import os
import re
import termios
import threading
import time
import tty

import pytest
import serial
from waiting import wait_until

from drivers.base import DeviceTimeout, DriverError
from drivers.serial_transport import SerialLineTransport, SerialPortError
from sim.devices.faults import FaultInjector, FaultSpec
from sim.devices.pty_server import PtyServer

GONE = r"{name}: serial port {port} went away \({action}.*\): \S"


def _check(exc_info, name, port, action):
    exc = exc_info.value
    assert isinstance(exc, DriverError) and not isinstance(exc, (OSError, termios.error))
    assert (exc.device, exc.port) == (name, port)
    assert re.match(GONE.format(name=name, port=re.escape(port), action=action), str(exc)), exc


def test_pm100_every_call_after_the_emulator_stops_is_a_port_error(pm_pair):
    emu, pm = pm_pair()
    port = emu.endpoint
    pm.read()
    emu.stop()
    calls = [pm.read, lambda: pm.wavelength_nm, pm.errors, pm.zero,
             lambda: setattr(pm, "averaging", 4), lambda: pm.configure(632.8, 1, None)]
    for call in calls:
        with pytest.raises(SerialPortError) as info:
            call()
        _check(info, "pm100", port, "discarding stale input")
    # what pyserial's read lets out for a port that hung up (the stale input is read out)
    assert isinstance(info.value.cause, serial.SerialException)
    pm.close()
    pm.close()  # closing a vanished port is quiet and idempotent


def test_esp_move_position_and_wait_after_the_emulator_stops(esp_pair):
    emu, ctl = esp_pair()
    port = emu.endpoint
    axis = ctl.axis(1)
    axis.move_to(10.0)
    emu.stop()
    for call in (axis.position, lambda: axis.move_to(20.0), lambda: axis.wait(1.0),
                 axis.stop, ctl.abort):
        with pytest.raises(SerialPortError) as info:
            call()
        _check(info, "esp", port, "discarding stale input")


@pytest.mark.parametrize("device", ["pm100", "esp"])
def test_emulator_stopping_while_a_reply_is_awaited(pm_pair, esp_pair, device):
    """The port vanishes while the driver blocks in read: it fails at once, not at timeout."""
    # a reply timeout beyond the suite's hang guard (300 s): a driver that waited for it, and
    # not for the port, would hang the test
    if device == "pm100":
        emu, drv = pm_pair(timeout_s=600.0)
        call, action = drv.read, "reading the reply to :READ"
    else:
        emu, drv = esp_pair(timeout_s=600.0)
        call, action = drv.axis(1).position, "reading the reply to 1TP"
    port = emu.endpoint
    emu.server.faults = FaultInjector(FaultSpec(stall_prob=1.0))  # the reply never comes

    def stop_once_asked() -> None:
        wait_until(lambda: emu.server.faults.counts["stall"] == 1, what="the request")
        emu.stop()

    stopper = threading.Thread(target=stop_once_asked)
    stopper.start()
    with pytest.raises(SerialPortError) as info:
        call()
    stopper.join()
    assert emu.server.faults.counts["stall"] == 1  # asked once: no timeout, so no retry
    _check(info, device, port, action)


def test_transport_open_of_a_vanished_pty_names_it():
    server = PtyServer(lambda line: line + b"\r\n", name="echo")
    port = server.start()
    server.stop()
    with pytest.raises(SerialPortError, match=f"echo: serial port {port} could not be opened"):
        SerialLineTransport(port, name="echo")


def test_transport_echo_session_then_hangup():
    server = PtyServer(lambda line: line + b"\r\n", name="echo")
    port = server.start()
    with SerialLineTransport(port, name="echo", timeout_s=0.5) as link:
        assert link.exchange("1TP?") == "1TP?"
        server.stop()
        with pytest.raises(DriverError, match=f"echo: serial port {re.escape(port)} went away"):
            link.exchange("1TP?")


def test_a_write_nobody_reads_times_out_by_name():
    """A pty whose far side is open but never read fills up: the write is bounded."""
    master, slave = os.openpty()
    try:
        tty.setraw(slave)
        with SerialLineTransport(os.ttyname(slave), name="stuck", timeout_s=0.3) as link:
            t0 = time.monotonic()
            with pytest.raises(DeviceTimeout, match=r"stuck: timeout after 0.3 s waiting for "
                               r"the port to take writing '(1TP\?){10}'\.\.\."):
                for _ in range(100):
                    link.send("1TP?" * 4000)
            assert time.monotonic() - t0 < 2.0
    finally:
        os.close(master)
        os.close(slave)
