"""Shared helpers of the Modbus tests: the shipped maps and endpoint arguments for drivers."""

import struct
from pathlib import Path

from sim.devices.modbus_server import ModbusEmulatorServer

MAPS = Path(__file__).resolve().parents[2] / "examples" / "registermaps"
STAGE_MAP = MAPS / "stepper-drive.toml"
DETECTOR_MAP = MAPS / "photodiode-adc.toml"
STAGE_UNIT, DETECTOR_UNIT, SECOND_STAGE_UNIT = 1, 2, 3


def crc16(data: bytes) -> bytes:
    """Modbus CRC-16 (poly 0xA001, init 0xFFFF), low byte first: written here, not imported."""
    crc = 0xFFFF
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = (crc >> 1) ^ 0xA001 if crc & 1 else crc >> 1
    return struct.pack("<H", crc)


def with_word_order(src: Path, order: str, folder: Path) -> Path:
    """A copy of a shipped map with its word_order replaced."""
    text = src.read_text().replace('word_order = "big"', f'word_order = "{order}"')
    out = folder / f"{src.stem}-{order}.toml"
    out.write_text(text)
    return out


def endpoint_args(server: ModbusEmulatorServer) -> tuple[str, str, dict]:
    """(transport, port_or_host, keyword args) for a driver of this server."""
    if server.transport == "tcp":
        host, port = server.endpoint.rsplit(":", 1)
        return "tcp", host, {"tcp_port": int(port)}
    return "rtu", server.endpoint, {}
