"""The verbs' --help says every exit status they give: `gonio scan` 2 for bad input and a device
that cannot be used before anything moves, `gonio devices` 0, 1 and 2; and `gonio emulate
--bind` names every emulator that listens on TCP (Modbus TCP and TCPIP SOCKET line devices).
What each status means is tested where it happens (tests/gonio/test_gonio_devices.py,
test_gonio_link_checks.py, tests/drivers/test_port_lock.py, test_gonio_bind.py)."""

from __future__ import annotations

import pytest

from gonio_cli.main import main


def help_text(verb: str, capsys) -> str:
    with pytest.raises(SystemExit) as done:
        main([verb, "--help"])
    assert done.value.code == 0
    return " ".join(capsys.readouterr().out.split())


def test_scan_help_lists_every_exit_status(capsys):
    text = help_text("scan", capsys)
    assert ("exit status: 0 completed, 1 failed, 2 bad input or a device that cannot be used "
            "(a plan or config that does not load, a port another process holds, a device that "
            "cannot be opened or refuses a setting: before anything moves), 130 aborted by "
            "Ctrl-C, 128 + N ended by signal N (SIGTERM, SIGHUP).") in text


def test_devices_help_lists_every_exit_status(capsys):
    text = help_text("devices", capsys)
    assert ("exit status: 0 every device answered, 1 some did not (its line says why; the "
            "others are still asked) or cannot measure as configured (its head's range leaves "
            "out the wavelength), 2 bad input (a config that does not load, a bad option).") in text


def test_emulate_help_names_every_tcp_emulator_bind_applies_to(capsys):
    text = help_text("emulate", capsys)
    assert "address the TCP emulators listen on, Modbus TCP and TCPIP SOCKET" in text
    assert "(Modbus TCP, and a line device given a TCPIP SOCKET resource)" in text
