"""`gonio scan --sim` with the PM100's console and sensor head chosen in [sim.devices.pm100]: a
source wavelength the head cannot take (1550 nm on a silicon S120C, 400-1100 nm) is one
error line naming the wavelength and the head's range, exit 2, and no run directory; a
germanium S122C takes it and the run records the console and head it met; a bad
[sim.devices] table is one line naming the key."""

import pytest
from gonio_testkit import fast_config, gonio_cli, one_line_error, run_dir_of, write_plan

from gonio.store import open_run

PLAN = {"name": "head", "averaging": 2, "grid": [
    {"side": "reflection", "theta_i_deg": [20.0], "theta_o_deg": [10.0, 30.0]}]}


def telecom_config(**pm100) -> dict:
    """The emulated serial bench lit at 1550 nm, its PM100 as [sim.devices.pm100] says (a
    generous meter timeout: the first reading at a new wavelength builds the bench's tables)."""
    cfg = fast_config(pm100={"timeout_s": 30.0})
    cfg["optics"]["wavelength_nm"] = 1550.0
    cfg["sim"]["devices"] = {"pm100": pm100}
    return cfg


def scan(tmp_path, cfg):
    plan = write_plan(tmp_path, PLAN, cfg)
    return gonio_cli("scan", plan, "--sim", "--out", tmp_path / "runs", "--no-plot",
                     "--no-progress")


def test_a_wavelength_the_silicon_head_cannot_take_is_one_error_and_no_run(tmp_path):
    proc = scan(tmp_path, telecom_config(sensor="S120C", model="PM100USB"))
    assert proc.returncode == 2
    assert one_line_error(proc.stderr) == (
        "gonio scan: error: pm100: wavelength 1550 nm is outside the sensor head S120C's "
        "range 400-1100 nm")
    assert proc.stdout == ""
    assert not (tmp_path / "runs").exists() or not any((tmp_path / "runs").iterdir())


def test_a_germanium_head_takes_it_and_the_run_records_console_and_head(tmp_path):
    proc = scan(tmp_path, telecom_config(sensor="S122C", model="PM100USB"))
    assert proc.returncode == 0, proc.stderr
    run = open_run(run_dir_of(proc))
    identity = run.meta["sessions"][0]["devices"]["pm100"]["identity"]
    assert identity["idn"].startswith("Thorlabs,PM100USB,")
    assert identity["sensor_name"] == "S122C"
    assert len(run.lines().rows) == 2


@pytest.mark.parametrize("table, message", [
    ({"pm100": {"sensor": "S999C"}},
     "[sim.devices.pm100] sensor: 'S999C' is not one of S120C, S121C, S130C, S122C, S302C"),
    ({"pm100": {"colour": "red"}},
     "[sim.devices.pm100] colour: the pm100 emulator takes no such key (keys: model, sensor)"),
    ({"esp": {"model": "ESP300"}},
     "[sim.devices.esp] model: the esp emulator takes no such key (keys: none)"),
    ({"meter": {"model": "PM100D"}}, "[sim.devices.meter]: no device 'meter' under [devices]"),
])
def test_a_bad_sim_devices_table_is_one_line_naming_the_key(tmp_path, table, message):
    cfg = fast_config()
    cfg["sim"]["devices"] = table
    proc = scan(tmp_path, cfg)
    assert proc.returncode == 2
    assert one_line_error(proc.stderr).endswith(message)
    assert not (tmp_path / "runs").exists() or not any((tmp_path / "runs").iterdir())
