"""What an emulator serves for a device a config gives by a VISA resource string, and the
resource a client then opens: a `TCPIP...::SOCKET` resource is served on raw TCP (at the
bench's listen address, 127.0.0.1 unless `gonio emulate --bind` names another), any other
(ASRL, USB-TMC, GPIB...) on a pty, opened as an ASRL resource (`ASRL/dev/pts/7::INSTR`)."""

from __future__ import annotations

import re

from sim.devices.pty_server import PtyDevice

SOCKET_RESOURCE = re.compile(r"TCPIP\d*::[^:]+::\d+::SOCKET", re.IGNORECASE)


def serve_resource(emulator: PtyDevice, resource: str, host: str) -> str:
    """Start the emulator on the link `resource` names as far as a test can reach it; the
    VISA resource string of what it serves."""
    if SOCKET_RESOURCE.fullmatch(resource.strip()):
        listening = emulator.start_tcp(host)
        address, port = listening.rsplit(":", 1)
        return f"TCPIP0::{address}::{port}::SOCKET"
    return f"ASRL{emulator.start()}::INSTR"
