"""gonio's and sim's device-kind registries name the same kinds in the same roles, and a
protocol neither knows is one clear error listing the kinds, in config and in emulate."""

import contextlib
import io
import tomllib
from pathlib import Path

import pytest

import gonio.device_kinds
import sim.device_kinds
from gonio.config import parse_config
from gonio.errors import ConfigError
from gonio_cli.main import main
from sim.devices.faults import KIND_FAULTS
from sim.devices.photodiode import SimConfigError
from sim.emulate import start

KIND_NAMES = ("esp, pm100, modbus-stage, modbus-detector, zaber, modbus-environment, fw102c, "
              "cornerstone")
SIM_SERIAL = Path(__file__).resolve().parents[1] / "examples" / "instruments" / "sim-serial.toml"
UNKNOWN_KIND = SIM_SERIAL.read_text().replace('protocol = "pm100"', 'protocol = "pm400"', 1)


def test_both_registries_name_the_same_kinds_in_the_same_roles():
    roles = {name: kind.role for name, kind in gonio.device_kinds.KINDS.items()}
    assert roles == {name: kind.role for name, kind in sim.device_kinds.KINDS.items()}
    assert set(roles.values()) == {"stage", "detector", "environment", "filter_wheel",
                                   "monochromator"}


def test_every_kind_fault_is_taken_by_some_kind_and_only_kind_faults_are_own():
    owned = {key for kind in sim.device_kinds.KINDS.values() for key in kind.own_faults}
    assert owned == set(KIND_FAULTS)


def test_an_unknown_protocol_is_one_config_error_listing_the_kinds():
    with pytest.raises(ConfigError) as err:
        parse_config(tomllib.loads(UNKNOWN_KIND))
    assert str(err.value) == (f"config: [devices.pm100] protocol: must be one of {KIND_NAMES}; "
                              "got 'pm400'")


def test_an_unknown_protocol_is_an_emulator_error_never_skipped():
    # only the stages are asked for: the detector of no known kind is refused all the same
    with pytest.raises(SimConfigError) as err:
        start(tomllib.loads(UNKNOWN_KIND), devices=["esp"])
    assert str(err.value) == (f"[devices.pm100] protocol 'pm400': no such device kind "
                              f"(kinds: {KIND_NAMES})")


def test_gonio_emulate_refuses_an_unknown_protocol_in_one_line(tmp_path):
    path = tmp_path / "cfg.toml"
    path.write_text(UNKNOWN_KIND)
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        code = main(["emulate", str(path)])
    assert code == 2
    assert err.getvalue() == (f"gonio emulate: error: {path}: [devices.pm100] protocol: must be "
                              f"one of {KIND_NAMES}; got 'pm400'\n")
