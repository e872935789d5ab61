"""An RTU device's line settings in a config: parity and stop bits as the Modbus serial-line
specification defaults them (even, 1), each bad value one error naming it, and the values
set on the real port the driver opens (on the emulated bus's pty)."""

import os
import termios
import tomllib
from pathlib import Path

import pytest
from gonio_testkit import fast_config

from drivers.byte_link import LineSettings, on_the_line
from gonio.config import parse_config
from gonio.errors import ConfigError
from gonio.instrument import build_instrument
from gonio.simulate import simulation


def modbus_config(**keys) -> dict:
    """sim-modbus.toml with `keys` set on its RTU photodiode amplifier."""
    cfg = fast_config("sim-modbus")
    cfg["devices"]["photodiode"].update(keys)
    return cfg


def test_an_rtu_line_defaults_to_the_modbus_specifications_even_parity():
    settings = parse_config(modbus_config()).devices["photodiode"].settings
    assert (settings["parity"], settings["stopbits"]) == ("even", 1)
    tcp = parse_config(modbus_config()).devices["sample_drive"].settings
    assert "parity" not in tcp and "stopbits" not in tcp  # a TCP unit has no line


@pytest.mark.parametrize("key, value, message", [
    ("parity", "E", "must be one of none, even, odd, mark, space; got 'E'"),
    ("stopbits", 0, "must be one of 1, 1.5, 2; got 0"),
])
def test_each_bad_rtu_line_setting_is_one_error_naming_it(key, value, message):
    with pytest.raises(ConfigError) as err:
        parse_config(modbus_config(**{key: value}))
    assert str(err.value) == f"config: [devices.photodiode] {key}: {message}"


def cflag_of(path: str) -> int:
    fd = os.open(path, os.O_RDWR | os.O_NOCTTY)
    try:
        return termios.tcgetattr(fd)[2]
    finally:
        os.close(fd)


@pytest.mark.parametrize("stopbits", [1, 2])
def test_the_stop_bits_reach_the_port_the_driver_opens(stopbits):
    # a pty keeps the stop bits it is set to but carries no parity bit: the driver opens the
    # emulator's pty without parity whatever the config says (the default, even, included)
    cfg = modbus_config(stopbits=stopbits)
    with simulation(parse_config(cfg)) as sim, build_instrument(sim.config, sim.time_scale) as ins:
        ins.detector.read()  # the RTU port opens at the first request
        path = sim.config.devices["photodiode"].endpoint
        assert bool(cflag_of(path) & termios.CSTOPB) == (stopbits == 2)
        port = ins.detector.link._client.socket
        assert (port.parity, port.stopbits) == ("N", stopbits)


def test_parity_is_dropped_on_a_pty_only():
    even = LineSettings(19200, parity="even")
    master, slave = os.openpty()
    try:
        assert on_the_line(even, Path(os.ttyname(slave))).parity == "none"
    finally:
        os.close(master)
        os.close(slave)
    assert on_the_line(even, Path("/dev/null")) == even  # a character device that is no pty
    assert on_the_line(even, None) == even  # a resource that names no file (USB, TCPIP)


def test_every_example_rtu_device_writes_its_parity():
    # the config's default is the Modbus specification's even parity, pymodbus's own was none:
    # a lab copying an example sees which its line is
    examples = Path(__file__).resolve().parents[2] / "examples" / "instruments"
    rtu = {f"{path.name} [devices.{name}]": table
           for path in sorted(examples.glob("*.toml"))
           for name, table in tomllib.loads(path.read_text())["devices"].items()
           if table.get("transport") == "rtu"}
    assert rtu, "no example has an RTU device"
    assert [where for where, table in rtu.items() if "parity" not in table] == []
