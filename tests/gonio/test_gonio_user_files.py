"""Files a user names (plans, the instrument config a plan names, register maps, calibration
files) must be regular files of bounded size (drivers.user_file): /dev/zero, a FIFO no one
writes, a folder or a file over the limit is one error line naming it, exit 2, no traceback and
no hang; and numeric settings have finite bounds, so `timeout_s = 1e300` is one error too."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from gonio_testkit import fast_config, write_plan, write_toml
from hostile_files import gonio_measured, refused

from drivers.register_map import RegisterMap, RegisterMapError
from drivers.user_file import SETTINGS_FILE_CAP
from gonio.config import parse_config
from gonio.device_kinds.settings import Setting
from gonio.errors import ConfigError

PLAN = {"name": "bounded", "sample": {"id": "bounded-test", "kind": "hemisphere", "eta": 1.51},
        "grid": [{"theta_i_deg": [30.0], "theta_o_deg": [10.0, 20.0]}]}


def plan_naming(folder: Path, instrument: str | Path) -> Path:
    """A plan whose `instrument` is the given path."""
    return write_toml(folder / "plan.toml", {**PLAN, "instrument": str(instrument)})


def test_plan_naming_dev_zero_as_its_instrument(tmp_path):
    """The attack: `instrument = "/dev/zero"` read until memory ran out."""
    plan = plan_naming(tmp_path, "/dev/zero")
    refused(gonio_measured("scan", plan, "--sim", "--out", tmp_path / "runs", "--no-plot"),
            Path("/dev/zero"), "instrument config must be a regular file, not a character device")


def test_plan_naming_a_fifo_as_its_instrument_does_not_hang(tmp_path):
    """The attack: a FIFO no one writes to, where opening it waited for a writer for ever."""
    fifo = tmp_path / "instrument.toml"
    os.mkfifo(fifo)
    refused(gonio_measured("plan", plan_naming(tmp_path, fifo)), fifo,
            "instrument config must be a regular file, not a FIFO")


@pytest.mark.parametrize("kind", ["fifo", "directory"])
def test_a_plan_that_is_not_a_regular_file(kind, tmp_path):
    plan = tmp_path / "plan.toml"
    os.mkfifo(plan) if kind == "fifo" else plan.mkdir()
    what = "a FIFO" if kind == "fifo" else "a directory"
    refused(gonio_measured("plan", plan), plan, f"plan must be a regular file, not {what}")


def test_a_plan_over_the_size_limit(tmp_path):
    plan = tmp_path / "plan.toml"
    with open(plan, "w") as fh:
        fh.write('name = "big"\n')
        fh.truncate(SETTINGS_FILE_CAP + 1)
    refused(gonio_measured("plan", plan), plan,
            f"plan is {SETTINGS_FILE_CAP + 1} bytes, over the {SETTINGS_FILE_CAP}-byte limit")


def test_a_calibration_file_that_is_a_fifo(tmp_path):
    fifo = tmp_path / "cal.json"
    os.mkfifo(fifo)
    refused(gonio_measured("calibrate", "show", fifo), fifo,
            "calibration file must be a regular file, not a FIFO")


def test_a_register_map_over_the_size_limit(tmp_path):
    path = tmp_path / "map.toml"
    with open(path, "w") as fh:
        fh.truncate(SETTINGS_FILE_CAP + 1)
    with pytest.raises(RegisterMapError, match=rf"map.toml: register map is "
                                               rf"{SETTINGS_FILE_CAP + 1} bytes, over the "):
        RegisterMap.load(path)


def test_timeout_of_1e300_is_one_error(tmp_path):
    """The attack: a device's `timeout_s = 1e300` overflowed select() mid-scan."""
    config = fast_config()
    config["devices"]["esp"]["timeout_s"] = 1e300
    plan = write_plan(tmp_path, PLAN, config)
    refused(gonio_measured("scan", plan, "--sim", "--out", tmp_path / "runs", "--no-plot"),
            tmp_path / "plan-instrument.toml",
            "[devices.esp] timeout_s: must be in (0, 3600], got 1e+300")


@pytest.mark.parametrize(("where", "key", "value"), [
    (("axes", "arm"), "speed_deg_s", 1e300),
    (("axes", "arm"), "accel_deg_s2", 1e300),
    (("axes", "arm"), "limits_deg", [-1e300, 1e300]),
    (("devices", "esp"), "baudrate", 10**30),
])
def test_numeric_settings_have_finite_bounds(where, key, value):
    config = fast_config()
    config[where[0]][where[1]][key] = value
    with pytest.raises(ConfigError, match=rf"\[{where[0]}.{where[1]}\] {key}: must be in "):
        parse_config(config)


def test_a_number_setting_declares_a_finite_upper_bound():
    with pytest.raises(ValueError, match="'rate_hz': a number needs a finite upper bound"):
        Setting("rate_hz", "number", 1.0, low=0.0)
