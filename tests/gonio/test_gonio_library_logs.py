"""What a library logs is not what gonio says: a Modbus drive refusing its TCP connection and
an RTU port that does not exist are each one line of `gonio devices`, and pymodbus's own
records (each failed connect, "Repeating....") never reach the user's stderr."""

import socket

from gonio_testkit import fast_config, gonio_cli, write_toml


def refused_port() -> int:
    """A TCP port on 127.0.0.1 nothing listens on (bound, then let go)."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def test_modbus_failures_are_gonios_lines_only(tmp_path):
    cfg = fast_config("sim-modbus")
    port = refused_port()
    for drive in ("sample_drive", "arm_drive"):
        cfg["devices"][drive].update(host="127.0.0.1", tcp_port=port)
    cfg["devices"]["photodiode"]["port"] = str(tmp_path / "ttyUSB9")
    proc = gonio_cli("devices", write_toml(tmp_path / "bench.toml", cfg))
    assert proc.returncode == 1
    lines = proc.stdout.splitlines()
    assert [line.split(" (")[0] for line in lines] == [
        "device sample_drive", "device arm_drive", "device photodiode"]
    assert all(": did not answer: " in line for line in lines)
    assert proc.stderr.splitlines() == [
        "gonio devices: 3 of 3 devices did not answer: sample_drive, arm_drive, photodiode"]
