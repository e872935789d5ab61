"""Devices read through their kinds' settings: endpoints both ways, what a session records,
and the Modbus kinds' own register-map checks, each one line naming the field."""

from pathlib import Path

import pytest
from gonio_testkit import fast_config

from gonio.config import parse_config
from gonio.device_kinds import Setting
from gonio.errors import ConfigError


@pytest.mark.parametrize("name", ["sim-serial", "sim-modbus", "lab"])
def test_a_device_is_pointed_at_its_own_endpoint_unchanged(name):
    for dev in parse_config(fast_config(name)).devices.values():
        values = dev.endpoint_values(dev.endpoint)
        assert values == {k: dev.settings[k] for k in values} and values
        assert dev.networked == ("host" in values)


def test_an_emulator_endpoint_becomes_host_and_integer_port():
    drive = parse_config(fast_config("sim-modbus")).devices["sample_drive"]
    assert drive.endpoint_values("127.0.0.1:15020") == {"host": "127.0.0.1", "tcp_port": 15020}
    assert drive.recorded == {"transport": "tcp", "unit": 1}


def test_only_modbus_devices_record_transport_and_unit():
    devices = parse_config(fast_config("sim-modbus")).devices | parse_config(
        fast_config("sim-serial")).devices
    assert {name: dev.recorded for name, dev in devices.items()} == {
        "sample_drive": {"transport": "tcp", "unit": 1},
        "arm_drive": {"transport": "tcp", "unit": 2},
        "photodiode": {"transport": "rtu", "unit": 3}, "esp": {}, "pm100": {}}


def test_a_modbus_stage_axis_its_map_cannot_encode_is_refused():
    cfg = fast_config("sim-modbus")
    cfg["axes"]["arm"]["speed_deg_s"] = 1000.0
    with pytest.raises(ConfigError, match=r"^config: \[axes\.arm\] speed_deg_s: the drive's "
                                          r"register map refuses it \(.*velocity = 1000\.0 "
                                          r"outside \[0\.001, 720\.0\] deg/s\)$"):
        parse_config(cfg)


def test_a_modbus_detector_map_that_does_not_load_is_refused(tmp_path):
    broken = tmp_path / "broken.toml"
    broken.write_text("registers = 3\n")
    cfg = fast_config("sim-modbus")
    cfg["devices"]["photodiode"]["register_map"] = str(broken)
    with pytest.raises(ConfigError, match=rf"^config: \[devices\.photodiode\] register_map: "
                                          rf"{broken}"):
        parse_config(cfg)


@pytest.mark.parametrize(("device", "line", "says"), [
    ("photodiode", 'range_gain_half_width_rel = "0.25 %"',
     r"\[specification\] range_gain_half_width_rel: must be a number in \[0, 1\) .*got "
     r"'0\.25 %'"),
    # a [detector]-style 1-sigma name is not a half-width: refused, not taken as one
    ("photodiode", "linearity_rel = 0.002", r"\[specification\]: unknown key 'linearity_rel'"),
    ("sample_drive", "repeatability_half_width_deg = -0.01",
     r"\[specification\] repeatability_half_width_deg: must be a number in \[0, 180\)"),
    ("sample_drive", "source = 3", r"\[specification\] source: must be a string")])
def test_a_register_map_specification_that_is_not_valid_is_refused(tmp_path, device, line, says):
    """A bad [specification] figure would otherwise give way to the default unseen: the
    config is refused when it loads, naming the map's file and the key."""
    cfg = fast_config("sim-modbus")
    shipped = Path(cfg["devices"][device]["register_map"])
    registers = shipped.read_text().split("[specification]")[0]  # the table ends the file
    bad = tmp_path / shipped.name
    bad.write_text(f"{registers}[specification]\n{line}\n")
    cfg["devices"][device]["register_map"] = str(bad)
    with pytest.raises(ConfigError, match=rf"^config: \[devices\.{device}\] register_map: "
                                          rf"{bad} {says}"):
        parse_config(cfg)


def test_a_setting_of_no_known_type_is_refused():
    with pytest.raises(ValueError, match="'strnig' is not one of"):
        Setting("port", "strnig")
