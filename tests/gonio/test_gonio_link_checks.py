"""Where a device is reached, checked when the config is read rather than when it opens: a
`resource` PyVISA cannot parse or that exchanges no lines, a VISA resource string given as a
`port`, a config with a resource and no PyVISA, mark parity that pyvisa-py cannot set on an
ASRL resource, and two devices reaching one device file or resource (but a Zaber chain's
devices and a Modbus bus's units share one by design, and agree on its settings). Each is one
error naming the field, and `gonio devices` refuses the config (exit 2) before anything opens.
A port is one however it is written (a /dev/serial/by-id symlink and its device file; device
names are case-sensitive): to the checks, the emulators and the drivers' shared link."""

import contextlib
import os
import sys
from pathlib import Path

import pytest
from gonio_testkit import fast_config, gonio_cli, one_line_error, write_toml

from drivers import byte_link
from gonio.config import parse_config
from gonio.device_kinds.settings import PARITY, STOPBITS
from gonio.errors import ConfigError
from gonio.simulate import simulation

USB_METER = "USB0::0x1313::0x8072::P2000000::INSTR"


def meter_by(cfg: dict, **link) -> dict:
    """The config with its meter reached by `link` (a port or a resource) instead."""
    for key in ("port", "resource"):
        cfg["devices"]["pm100"].pop(key, None)
    cfg["devices"]["pm100"].update(link)
    return cfg


def refused(cfg: dict) -> str:
    with pytest.raises(ConfigError) as err:
        parse_config(cfg)
    return str(err.value)


@pytest.mark.parametrize("resource, why", [
    ("garbage", "Could not parse garbage: unknown interface type"),
    ("ASRL/dev/pts/1::INSTRR", "Could not parse 'ASRL/dev/pts/1::INSTRR'. The syntax is "
                               "'ASRL[board][::INSTR]' (too many parts)."),
    ("GPIB0::INTFC", "INTFC resources exchange no lines; give an INSTR or SOCKET resource"),
    ("USB0::0x1313::0x8072::P2000000::RAW",
     "RAW resources exchange no lines; give an INSTR or SOCKET resource"),
    ("USB0::0x1313::0x8072::P2000000::INSTRR",  # PyVISA: interface "INSTRR" of an INSTR
     "its USB interface number 'INSTRR' is not a number (a USB resource is USB<board>::"
     "<vendor id>::<product id>::<serial>[::<interface>]::INSTR)"),
    ("USB0::0x13G3::0x8072::P2000000::INSTR",
     "its USB vendor id '0x13G3' is not a number (a USB resource is USB<board>::"
     "<vendor id>::<product id>::<serial>[::<interface>]::INSTR)"),
])
def test_a_resource_is_parsed_when_the_config_is_read(resource, why):
    assert refused(meter_by(fast_config(), resource=resource)) == (
        f"config: [devices.pm100] resource: {resource!r} is not a VISA resource a line device "
        f"is reached by: {why}")


def test_gonio_devices_refuses_a_bad_resource_before_opening_anything(tmp_path):
    path = write_toml(tmp_path / "bad.toml", meter_by(fast_config(), resource="garbage"))
    for sim in ((), ("--sim",)):
        proc = gonio_cli("devices", path, *sim)
        assert proc.returncode == 2, proc.stdout + proc.stderr
        assert one_line_error(proc.stderr).startswith(
            f"gonio devices: error: {path}: [devices.pm100] resource: 'garbage' is not a VISA ")
        assert proc.stdout == ""


def test_a_visa_resource_string_given_as_a_port_points_at_resource():
    assert refused(meter_by(fast_config(), port=USB_METER)) == (
        f"config: [devices.pm100] port: {USB_METER!r} is a VISA resource string, not a serial "
        f'port; give it as resource = "{USB_METER}"')


def test_a_modbus_line_given_a_visa_resource_string_asks_for_its_device_file():
    cfg = fast_config("sim-modbus")
    cfg["devices"]["photodiode"]["port"] = "ASRL/dev/ttyUSB2::INSTR"
    assert refused(cfg) == ("config: [devices.photodiode] port: 'ASRL/dev/ttyUSB2::INSTR' is "
                            "a VISA resource string, not a serial port; give the line's device "
                            "file, such as /dev/ttyUSB0")


def test_a_resource_without_pyvisa_is_one_error_saying_what_to_install(monkeypatch):
    monkeypatch.setitem(sys.modules, "pyvisa", None)  # as on a machine without gonio[visa]
    assert refused(meter_by(fast_config(), resource=USB_METER)) == (
        "config: [devices.pm100] resource: PyVISA is not installed (pip install "
        "'gonio[visa]'): a VISA resource is opened through it")
    parse_config(fast_config())  # a config of ports needs no PyVISA


def test_mark_parity_on_an_asrl_resource_is_refused_on_pyvisa_py_only(monkeypatch):
    monkeypatch.delenv("GONIO_VISA_LIBRARY", raising=False)
    asrl = "ASRL/dev/ttyUSB1::INSTR"
    assert refused(meter_by(fast_config(), resource=asrl, parity="mark")) == (
        f"config: [devices.pm100] parity: pyvisa-py cannot set mark parity on {asrl} "
        f'(VI_ERROR_NSUP_ATTR_STATE); give the port as port = "/dev/ttyUSB1", or open it '
        f"through another VISA (GONIO_VISA_LIBRARY=@ivi)")
    for fine in (meter_by(fast_config(), resource=asrl, parity="space"),
                 meter_by(fast_config(), port="/dev/ttyUSB1", parity="mark"),
                 meter_by(fast_config(), resource=USB_METER, parity="mark")):
        parse_config(fine)  # pyvisa-py sets space; pyserial sets mark; USB-TMC has no parity
    monkeypatch.setenv("GONIO_VISA_LIBRARY", "@ivi")
    parse_config(meter_by(fast_config(), resource=asrl, parity="mark"))


def test_the_line_settings_offer_the_links_own_choices():
    assert PARITY.choices == byte_link.PARITIES and STOPBITS.choices == byte_link.STOPBITS


def test_a_port_and_a_resource_on_one_device_file_are_one_error_naming_both(tmp_path):
    leader, follower = os.openpty()
    try:
        pty = os.ttyname(follower)
        alias = tmp_path / "by-id-esp"
        alias.symlink_to(pty)  # a /dev/serial/by-id name of the same device
        cfg = fast_config()
        cfg["devices"]["esp"]["port"] = pty
        assert refused(meter_by(cfg, resource=f"ASRL{pty}::INSTR")) == (
            f"config: [devices.esp] port and [devices.pm100] resource both reach {pty}: one "
            f"device file or resource reaches one device")
        cfg["devices"]["esp"]["port"] = str(alias)
        assert refused(meter_by(cfg, port=pty)) == (
            f"config: [devices.esp] port and [devices.pm100] port both reach {pty}: one device "
            f"file or resource reaches one device")
    finally:
        os.close(leader)
        os.close(follower)


def test_one_usb_resource_spelt_two_ways_is_one_device():
    cfg = fast_config()
    del cfg["devices"]["esp"]["port"]
    cfg["devices"]["esp"]["resource"] = "USB::0x1313::0x8072::P2000000::INSTR"
    assert refused(meter_by(cfg, resource=USB_METER)) == (
        "config: [devices.esp] resource and [devices.pm100] resource both reach "
        "USB0::0x1313::0x8072::P2000000::0::INSTR: one device file or resource reaches one "
        "device")


def zaber_chain(*addresses: int) -> dict:
    """The Zaber bench with one more device per address, all on the chain's port."""
    cfg = fast_config("sim-zaber")
    first = cfg["devices"]["zaber"]
    first["address"] = addresses[0]
    for n, address in enumerate(addresses[1:], 2):
        cfg["devices"][f"zaber{n}"] = dict(first, address=address)
    return cfg


def test_a_zaber_chain_shares_its_port_by_address():
    parse_config(zaber_chain(1, 2, 3))
    assert refused(zaber_chain(1, 2, 2)) == (
        "config: [devices.zaber2] port and [devices.zaber3] port both reach /dev/ttyUSB0 at "
        "address 2")


def test_a_modbus_bus_shares_its_port_by_unit():
    cfg = fast_config("sim-modbus")
    photodiode = cfg["devices"]["photodiode"]
    cfg["devices"]["amplifier"] = dict(photodiode, unit=photodiode["unit"] + 1)
    parse_config(cfg)
    cfg["devices"]["amplifier"]["unit"] = photodiode["unit"]
    assert refused(cfg) == ("config: [devices.photodiode] port and [devices.amplifier] port "
                            f"both reach /dev/ttyUSB2 at unit {photodiode['unit']}")


def test_devices_of_other_kinds_never_share_a_port():
    cfg = fast_config("sim-zaber")
    cfg["devices"]["pm100"]["port"] = cfg["devices"]["zaber"]["port"]
    assert refused(cfg) == ("config: [devices.zaber] port and [devices.pm100] port both reach "
                            "/dev/ttyUSB0: one device file or resource reaches one device")


def test_device_paths_that_differ_in_case_are_different_devices():
    cfg = fast_config("sim-zaber")
    cfg["devices"]["pm100"]["port"] = cfg["devices"]["zaber"]["port"].lower()  # /dev/ttyusb0
    assert cfg["devices"]["pm100"]["port"] != cfg["devices"]["zaber"]["port"]
    parse_config(cfg)  # Linux's device names are case-sensitive: two ports


def rtu_bus(alias: Path, **amplifier) -> dict:
    """The Modbus bench with a second amplifier on the photodiode's RTU bus, its port written
    as `alias`, a /dev/serial/by-id symlink to the bus's device file, and `amplifier` set on
    it."""
    cfg = fast_config("sim-modbus")
    photodiode = cfg["devices"]["photodiode"]
    if not alias.is_symlink():
        alias.symlink_to(photodiode["port"])
    cfg["devices"]["amplifier"] = dict(photodiode, port=str(alias),
                                       unit=photodiode["unit"] + 1, **amplifier)
    return cfg


@pytest.mark.parametrize("key, value, mine, theirs", [
    ("baudrate", 9600, "9600", "115200"),
    ("parity", "none", '"none"', '"even"'),
    ("stopbits", 2, "2.0", "1.0"),
    ("timeout_s", 2.0, "2.0", "0.5"),
])
def test_the_units_of_a_modbus_bus_agree_on_its_line(tmp_path, key, value, mine, theirs):
    alias = tmp_path / "usb-FTDI_USB-RS485_Cable-if00-port0"
    parse_config(rtu_bus(alias))  # one bus, written two ways, told apart by unit
    assert refused(rtu_bus(alias, **{key: value})) == (
        f"config: [devices.amplifier] {key}: {mine} differs from "
        f"[devices.photodiode]'s {theirs}: both are on the Modbus link at /dev/ttyUSB2, one "
        "line with one setting")


def test_the_units_of_a_modbus_tcp_server_agree_on_its_timeout():
    cfg = fast_config("sim-modbus")
    cfg["devices"]["arm_drive"]["timeout_s"] = 2.0
    assert refused(cfg) == (
        "config: [devices.arm_drive] timeout_s: 2.0 differs from [devices.sample_drive]'s 0.5: "
        "both are on the Modbus link at 192.168.0.20:502, one line with one setting")
    cfg["devices"]["arm_drive"]["tcp_port"] = 503  # another server: a link of its own
    parse_config(cfg)


def test_a_bus_written_two_ways_is_one_emulated_bus_and_one_link(tmp_path):
    cfg = parse_config(rtu_bus(tmp_path / "usb-FTDI_USB-RS485_Cable-if00-port0"))
    with simulation(cfg) as sim:
        assert sim.bench.emulators["amplifier"] is sim.bench.emulators["photodiode"]
        units = [sim.config.devices[name] for name in ("photodiode", "amplifier")]
        assert units[0].endpoint == units[1].endpoint
        with contextlib.ExitStack() as opened:
            photodiode, amplifier = (opened.enter_context(dev.kind.open(dev)) for dev in units)
            assert amplifier.link is photodiode.link
            assert [unit.identity()["serial"] for unit in (photodiode, amplifier)] == [
                "SIM00004", "SIM00005"]
