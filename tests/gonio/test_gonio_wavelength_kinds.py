"""The filter wheel and monochromator kinds in an instrument config: their settings read and
checked (one clear error per bad setting, naming it), and their emulators started by `sim`
and opened through the kinds, over real ptys."""

import tomllib
from pathlib import Path

import pytest
from gonio_testkit import fast_config, gonio_cli, write_toml

from drivers.base import WavelengthSelector
from gonio.config import parse_config
from gonio.errors import ConfigError
from gonio.simulate import point_at
from sim.emulate import start

SIM_SERIAL = Path(__file__).resolve().parents[2] / "examples" / "instruments" / "sim-serial.toml"
SELECTORS = """
[devices.wheel]
protocol = "fw102c"
port = "/dev/ttyUSB7"

[devices.wheel.filters]
1 = { centre_nm = 450.0, bandwidth_nm = 10.0 }
3 = { centre_nm = 532.0, bandwidth_nm = 3.0 }

[devices.mono]
protocol = "cornerstone"
port = "/dev/ttyUSB8"
grating = 2
"""


def config(**wheel) -> dict:
    """sim-serial with the wheel and the monochromator, the wheel's settings replaced."""
    raw = tomllib.loads(SIM_SERIAL.read_text() + SELECTORS)
    for key, value in wheel.items():
        if value is None:
            del raw["devices"]["wheel"][key]
        else:
            raw["devices"]["wheel"][key] = value
    return raw


def test_the_kinds_read_their_settings_with_the_manuals_line_defaults():
    cfg = parse_config(config())
    wheel, mono = cfg.devices["wheel"], cfg.devices["mono"]
    assert wheel.kind.role == "filter_wheel" and mono.kind.role == "monochromator"
    assert wheel.settings["filters"] == ((1, 450.0, 10.0), (3, 532.0, 3.0))
    assert (wheel.settings["baudrate"], wheel.settings["positions"],
            wheel.settings["speed"]) == (115200, 6, "high")
    assert (mono.settings["baudrate"], mono.settings["grating"]) == (9600, 2)


@pytest.mark.parametrize("wheel, message", [
    ({"filters": None}, "[devices.wheel]: missing required key 'filters'"),
    ({"filters": 450.0}, "[devices.wheel] filters: must be a table of positions, each "
                         "{centre_nm, bandwidth_nm}, with at least one filter; got 450.0"),
    ({"filters": {}}, "[devices.wheel] filters: must be a table of positions"),
    ({"filters": {"0": {"centre_nm": 450.0, "bandwidth_nm": 10.0}}},
     "[devices.wheel] filters.0: a position must be a whole number 1..12"),
    ({"filters": {"x": {"centre_nm": 450.0, "bandwidth_nm": 10.0}}},
     "[devices.wheel] filters.x: a position must be a whole number 1..12"),
    ({"filters": {"1": 450.0}}, "[devices.wheel.filters.1]: must be a table, got 450.0"),
    ({"filters": {"1": {"centre_nm": 450.0}}},
     "[devices.wheel.filters.1]: missing required key 'bandwidth_nm'"),
    ({"filters": {"1": {"centre_nm": -450.0, "bandwidth_nm": 10.0}}},
     "[devices.wheel.filters.1] centre_nm: must be in (0, 100000], got -450.0"),
    ({"filters": {"1": {"centre_nm": 450.0, "bandwidth_nm": 0}}},
     "[devices.wheel.filters.1] bandwidth_nm: must be in (0, 100000], got 0"),
    ({"filters": {"1": {"centre_nm": 450.0, "bandwidth_nm": 10.0, "colour": "blue"}}},
     "[devices.wheel.filters.1]: unknown key 'colour'"),
    ({"filters": {"1": {"centre_nm": 450.0, "bandwidth_nm": 10.0},
                  "2": {"centre_nm": 450.0, "bandwidth_nm": 40.0}}},
     "[devices.wheel] filters.2: centre_nm 450 is also position 1's: a wavelength must name "
     "one filter"),
    ({"filters": {"9": {"centre_nm": 450.0, "bandwidth_nm": 10.0}}},
     "[devices.wheel] filters.9: position 9 is beyond the wheel's 6 positions (positions)"),
    ({"positions": 8}, "[devices.wheel] positions: must be one of 6, 12; got 8"),
    ({"speed": "fast"}, "[devices.wheel] speed: must be one of high, slow; got 'fast'"),
    ({"grating": 2}, "[devices.wheel]: unknown key 'grating'"),
])
def test_each_bad_wheel_setting_is_one_error_naming_it(wheel, message):
    with pytest.raises(ConfigError) as err:
        parse_config(config(**wheel))
    assert str(err.value).startswith(f"config: {message}")


def test_a_monochromator_grating_out_of_range_is_refused():
    raw = config()
    raw["devices"]["mono"]["grating"] = 4
    with pytest.raises(ConfigError, match=r"^config: \[devices\.mono\] grating: must be in "
                                          r"\[1, 3\], got 4$"):
        parse_config(raw)


def test_sim_serves_both_and_the_kinds_open_them_as_wavelength_selectors():
    cfg = parse_config(config())
    bench = start(cfg.raw, devices=["wheel", "mono"])
    try:
        served = point_at(cfg, {name: bench.endpoints[name].endpoint for name in ("wheel", "mono")})
        assert {bench.endpoints[n].protocol for n in ("wheel", "mono")} == {"fw102c",
                                                                            "cornerstone"}
        for name, wavelength_nm in (("wheel", 532.0), ("mono", 587.6)):
            dev = served.devices[name]
            selector = dev.kind.open(dev)
            try:
                assert isinstance(selector, WavelengthSelector)
                selector.move_to_nm(wavelength_nm)
                assert selector.wait(60.0) == wavelength_nm
                assert selector.identity()
            finally:
                selector.close()
        assert bench.emulators["mono"].grating == 2
    finally:
        bench.stop()


def test_gonio_devices_sim_identifies_both(tmp_path):
    cfg = fast_config("sim-serial")
    cfg["devices"].update(tomllib.loads(SELECTORS)["devices"])
    proc = gonio_cli("devices", "--sim", write_toml(tmp_path / "spectral.toml", cfg))
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    wheel = next(line for line in lines if line.startswith("device wheel "))
    mono = next(line for line in lines if line.startswith("device mono "))
    assert wheel.startswith("device wheel (fw102c at /dev/pts/")
    assert wheel.endswith("): idn: THORLABS FW102C/FW212C Filter Wheel version 1.07")
    assert mono.startswith("device mono (cornerstone at /dev/pts/")
    assert mono.endswith("): info: CS130B V2.00")
