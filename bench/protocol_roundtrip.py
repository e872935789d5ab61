"""Position-query round trips per second of each driver and emulator, beside bare echo.

Round trips per second of a position query through each driver and emulator, beside the
bare transport's echo round trip measured in the same run (the floor no protocol can beat).

- ESP300/301 over a pty: EspAxis.position() (a "1TP?" query) vs a pty echo of the same bytes
  through pyserial.
- PM100 through the same driver (Pm100.measure(): MEAS:POW? with the range and the error
  status, one line each way) over each link it may be given: a pty through pyserial, the same
  pty through PyVISA as an ASRL resource, and raw TCP on 127.0.0.1 through PyVISA as a TCPIP
  SOCKET resource (pyvisa-py); beside each, plain PyVISA querying the same message (no gonio
  driver), and the pty or TCP echo of the request.
- Modbus TCP on 127.0.0.1: ModbusStage.position() (function 03, two registers) vs a TCP echo
  of a 12-byte request on a plain socket.
- Modbus RTU over a pty: the same driver call vs the pty echo (the emulator serves the
  pty's master on its event loop: the same single pty hop as the echo).
- Each Modbus transport also times, on the same emulator, stock pymodbus's own sync client
  (what pymodbus alone gives; its RTU client polls the port every millisecond) and the raw
  request frame written and its reply read back with no client library (what the emulator
  itself costs: the floor of any client on it).

Every figure is the best of five slices of --seconds (default 1.0). Run:
python bench/protocol_roundtrip.py [--seconds 1.0]   (figures are noisy on a shared machine:
the load average is printed before and after)
"""

from __future__ import annotations

import argparse
import math
import os
import select
import socket
import threading
import time
import tty
from collections.abc import Callable
from pathlib import Path

import serial
from pymodbus.client import ModbusSerialClient, ModbusTcpClient

from drivers.esp import EspController
from drivers.modbus_stage import ModbusStage
from drivers.pm100 import Pm100
from sim.devices.esp import EspEmulator
from sim.devices.modbus_server import ModbusEmulatorServer
from sim.devices.modbus_stage import ModbusStageEmulator
from sim.devices.motion import VirtualClock
from sim.devices.photodiode import ConstantPower
from sim.devices.pm100 import Pm100Emulator
from sim.served_resources import serve_resource

STAGE_MAP = Path(__file__).resolve().parents[1] / "examples" / "registermaps" / "stepper-drive.toml"
ESP_QUERY = b"1TP?\r"
PM100_QUERY = ":MEAS:POW?;:SENS:POW:RANG?;:SYST:ERR?"  # what Pm100.measure() sends
#: the meter's links: what a config names, served by the emulator as sim serves it
PM100_LINKS = {"ASRL": "USB0::0x1313::0x8072::P2000000::INSTR",
               "TCPIP SOCKET": "TCPIP0::127.0.0.1::5025::SOCKET"}
MODBUS_TCP_REQUEST = bytes.fromhex("000100000006010300080002")  # read holding 8..9 of unit 1
MODBUS_TCP_REPLY_BYTES = 13  # MBAP 7 + function, byte count, 4 data bytes
MODBUS_RTU_REQUEST = bytes.fromhex("01030008000245c9")  # the same read as an RTU frame
MODBUS_RTU_REPLY_BYTES = 9  # unit, function, byte count, 4 data bytes, CRC


def rate(call: Callable[[], object], seconds: float, slices: int = 5) -> float:
    """Calls per second of call(): the best of `slices` runs of seconds/slices each, after a
    few warm-up calls (on a shared machine the best slice is the one least disturbed)."""
    for _ in range(20):
        call()
    best = 0.0
    for _ in range(slices):
        n, t0 = 0, time.perf_counter()
        while (elapsed := time.perf_counter() - t0) < seconds / slices:
            for _ in range(20):
                call()
            n += 20
        best = max(best, n / elapsed)
    return best


class PtyEcho:
    """A thread echoing every byte written to a pty back to the writer (the pty floor)."""

    def __init__(self):
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        self.path = os.ttyname(self.slave)
        self._wake_r, self._wake_w = os.pipe()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while True:
            ready, _, _ = select.select([self.master, self._wake_r], [], [])
            if self._wake_r in ready:
                return
            os.write(self.master, os.read(self.master, 4096))

    def close(self) -> None:
        os.write(self._wake_w, b"x")
        self._thread.join(2.0)
        for fd in (self.master, self.slave, self._wake_r, self._wake_w):
            os.close(fd)


class TcpEcho:
    """A thread echoing one TCP connection on 127.0.0.1 (the socket floor)."""

    def __init__(self):
        self._listener = socket.create_server(("127.0.0.1", 0))
        self.port = self._listener.getsockname()[1]
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        conn, _ = self._listener.accept()
        conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        with conn:
            while data := conn.recv(4096):
                conn.sendall(data)

    def close(self) -> None:
        self._listener.close()
        self._thread.join(2.0)


def pty_echo_rate(payload: bytes, seconds: float) -> float:
    """Echo round trips per second of payload through a pty, pyserial on the host side."""
    echo = PtyEcho()
    port = serial.Serial(echo.path, 115200, timeout=1.0)
    try:
        return rate(lambda: (port.write(payload), port.read(len(payload))), seconds)
    finally:
        port.close()
        echo.close()


def tcp_echo_rate(payload: bytes, seconds: float) -> float:
    """Echo round trips per second of payload over TCP on 127.0.0.1."""
    echo = TcpEcho()
    sock = socket.create_connection(("127.0.0.1", echo.port))
    sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)

    def once() -> None:
        sock.sendall(payload)
        got = b""
        while len(got) < len(payload):
            got += sock.recv(4096)

    try:
        return rate(once, seconds)
    finally:
        sock.close()
        echo.close()


def esp_rate(seconds: float) -> float:
    """EspAxis.position() round trips per second on the ESP emulator over a pty."""
    emulator = EspEmulator(VirtualClock(math.inf), {1: {}})
    emulator.start()
    try:
        with EspController(emulator.endpoint, timeout_s=1.0) as controller:
            axis = controller.axis(1, "bench")
            return rate(axis.position, seconds)
    finally:
        emulator.stop()


def pm100_serial_rate(seconds: float) -> float:
    """Pm100.measure() round trips per second on the PM100 emulator over a pty (pyserial)."""
    emulator = Pm100Emulator(ConstantPower(2e-6))
    emulator.start()
    try:
        with Pm100(emulator.endpoint, timeout_s=1.0) as meter:
            return rate(meter.measure, seconds)
    finally:
        emulator.stop()


def pm100_visa_rates(link: str, seconds: float) -> tuple[float, float]:
    """Round trips per second on the PM100 emulator served for a `link` resource, through
    PyVISA: Pm100.measure() given the resource, and plain PyVISA querying the same line."""
    import pyvisa

    emulator = Pm100Emulator(ConstantPower(2e-6))
    resource = serve_resource(emulator, PM100_LINKS[link], "127.0.0.1")
    try:
        with Pm100(resource=resource, timeout_s=1.0) as meter:
            driver = rate(meter.measure, seconds)
        port = pyvisa.ResourceManager("@py").open_resource(
            resource, read_termination="\n", write_termination="\n", timeout=1000)
        try:
            bare = rate(lambda: port.query(PM100_QUERY), seconds)
        finally:
            port.close()
        return driver, bare
    finally:
        emulator.stop()


def modbus_rates(transport: str, seconds: float) -> tuple[float, float, float]:
    """Round trips per second on the Modbus emulator: ModbusStage.position(), stock pymodbus's
    client reading the same two registers, and the raw request frame with no client."""
    unit = ModbusStageEmulator(VirtualClock(math.inf), STAGE_MAP, (-95.0, 95.0), 20.0, 80.0)
    server = ModbusEmulatorServer(transport, {1: unit})
    endpoint = server.start()
    host, port = endpoint.rsplit(":", 1) if transport == "tcp" else (endpoint, "502")
    try:
        with ModbusStage(transport, host, 1, STAGE_MAP, tcp_port=int(port)) as stage:
            driver = rate(stage.position, seconds)
        client = (ModbusTcpClient(host, port=int(port)) if transport == "tcp"
                  else ModbusSerialClient(host, baudrate=115200))
        client.connect()
        try:
            bare = rate(lambda: client.read_holding_registers(8, count=2, device_id=1), seconds)
        finally:
            client.close()
        raw = (raw_tcp_rate(host, int(port), seconds) if transport == "tcp"
               else raw_rtu_rate(host, seconds))
        return driver, bare, raw
    finally:
        server.stop()


def raw_tcp_rate(host: str, port: int, seconds: float) -> float:
    """The 12-byte read request on a plain socket, its 13-byte reply read back, per second."""
    sock = socket.create_connection((host, port))
    sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)

    def once() -> None:
        sock.sendall(MODBUS_TCP_REQUEST)
        got = b""
        while len(got) < MODBUS_TCP_REPLY_BYTES:
            got += sock.recv(4096)

    try:
        return rate(once, seconds)
    finally:
        sock.close()


def raw_rtu_rate(path: str, seconds: float) -> float:
    """The 8-byte RTU read request through pyserial, its 9-byte reply read back, per second."""
    port = serial.Serial(path, 115200, timeout=1.0)

    def once() -> None:
        port.write(MODBUS_RTU_REQUEST)
        if len(port.read(MODBUS_RTU_REPLY_BYTES)) != MODBUS_RTU_REPLY_BYTES:
            raise RuntimeError("the RTU emulator did not answer a raw read request")

    try:
        return rate(once, seconds)
    finally:
        port.close()


def load() -> str:
    """The 1, 5 and 15 minute load averages (the machine is shared: figures move with it)."""
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=1.0, help="time per measurement")
    args = parser.parse_args()
    s = args.seconds
    print(f"load average before: {load()} ({os.cpu_count()} cores)")
    tcp_driver, tcp_bare, tcp_raw = modbus_rates("tcp", s)
    tcp_echo = tcp_echo_rate(MODBUS_TCP_REQUEST, s)
    rtu_driver, rtu_bare, rtu_raw = modbus_rates("rtu", s)
    rtu_echo = pty_echo_rate(MODBUS_RTU_REQUEST, s)
    tcp_floor, rtu_floor = "TCP echo, 12 bytes", "pty echo, 8 bytes"
    pm100_request = PM100_QUERY.encode() + b"\n"
    pm100_floor = f"pty echo, {len(pm100_request)} bytes"
    pm100_echo = pty_echo_rate(pm100_request, s)
    pm100_tcp_floor = f"TCP echo, {len(pm100_request)} bytes"
    pm100_tcp_echo = tcp_echo_rate(pm100_request, s)
    asrl_driver, asrl_bare = pm100_visa_rates("ASRL", s)
    socket_driver, socket_bare = pm100_visa_rates("TCPIP SOCKET", s)
    rows = [
        ("ESP TP? over pty (EspAxis.position)", esp_rate(s),
         "pty echo, 5 bytes", pty_echo_rate(ESP_QUERY, s)),
        ("PM100 MEAS:POW? over pty (Pm100.measure)", pm100_serial_rate(s), pm100_floor,
         pm100_echo),
        ("PM100 MEAS:POW? PyVISA ASRL (Pm100.measure)", asrl_driver, pm100_floor, pm100_echo),
        ("PM100 MEAS:POW? PyVISA ASRL (plain query)", asrl_bare, pm100_floor, pm100_echo),
        ("PM100 MEAS:POW? PyVISA SOCKET (Pm100.measure)", socket_driver, pm100_tcp_floor,
         pm100_tcp_echo),
        ("PM100 MEAS:POW? PyVISA SOCKET (plain query)", socket_bare, pm100_tcp_floor,
         pm100_tcp_echo),
        ("Modbus TCP read 2 regs (ModbusStage.position)", tcp_driver, tcp_floor, tcp_echo),
        ("Modbus TCP read 2 regs (stock pymodbus client)", tcp_bare, tcp_floor, tcp_echo),
        ("Modbus TCP read 2 regs (raw frame, no client)", tcp_raw, tcp_floor, tcp_echo),
        ("Modbus RTU read 2 regs (ModbusStage.position)", rtu_driver, rtu_floor, rtu_echo),
        ("Modbus RTU read 2 regs (stock pymodbus client)", rtu_bare, rtu_floor, rtu_echo),
        ("Modbus RTU read 2 regs (raw frame, no client)", rtu_raw, rtu_floor, rtu_echo),
    ]
    print(f"{'protocol round trip':48s} {'per s':>9s}   {'floor (same run)':20s} {'per s':>9s}"
          f"  {'ratio':>6s}")
    for name, value, floor_name, floor in rows:
        print(f"{name:48s} {value:9.0f}   {floor_name:20s} {floor:9.0f}  {value / floor:6.3f}")
    print(f"load average after: {load()}")


if __name__ == "__main__":
    main()
