"""Hardware in the loop. A lab rehearsal with two processes: `gonio emulate lab.toml` serves
the lab's devices (ESP301 and PM100 on ptys, a Modbus TCP drive on loopback) and
`gonio scan PLAN --instrument` runs against them through exactly the lab code path. Then a
mixed run: the stages from the other process, the detector emulated in the scanning process
(`--sim detector`), seeing the positions the stages report."""


import numpy as np
import pytest
from gonio_testkit import emulating, gonio_cli, load_example, pointed, run_dir_of, write_toml

from gonio.store import open_run

PLAN = {"name": "rehearsal", "dark": {"every": 6}, "beam": {"every": 6}, "grid": [
    {"side": ["reflection", "transmission"], "theta_i_deg": [20.0],
     "theta_o_deg": [10.0, 30.0], "phi_o_deg": [0.0, 25.0], "sample_azimuth_deg": [0.0, 45.0]}]}


def rehearsal_config():
    """lab.toml, made quick: instant motion, cheap aperture rule, short settling."""
    cfg = load_example("lab")
    cfg["sim"].update(time_scale="inf")
    cfg["sim"].setdefault("aperture", {})["order"] = [0, 0]
    for axis in cfg["axes"].values():
        axis["settle_s"] = 0.0
    return cfg


@pytest.fixture
def emulated_lab(tmp_path):
    """`gonio emulate` in its own process; yields (config, {device: (protocol, endpoint)})."""
    cfg = rehearsal_config()
    with emulating(write_toml(tmp_path / "lab.toml", cfg)) as endpoints:
        yield cfg, endpoints


def test_two_process_rehearsal(emulated_lab, tmp_path):
    cfg, endpoints = emulated_lab
    assert {p for p, _ in endpoints.values()} == {"esp", "pm100", "modbus-tcp"}
    assert endpoints["esp"][1].startswith("/dev/pts/")
    instrument = write_toml(tmp_path / "rehearsal.toml", pointed(cfg, endpoints))
    plan = write_toml(tmp_path / "plan.toml", PLAN)
    proc = gonio_cli("scan", plan, "--instrument", instrument, "--out", tmp_path / "runs",
                     "--no-plot")
    assert proc.returncode == 0, proc.stderr
    run = open_run(run_dir_of(proc))
    assert run.meta["sim"] is False and run.meta["status"] == "completed"
    devices = run.meta["sessions"][0]["devices"]  # each named by what it reported
    assert {n: d["endpoint"] for n, d in devices.items()} == {n: e for n, (_, e) in
                                                             endpoints.items()}
    assert devices["esp"]["identity"]["version"].startswith("ESP301 Version")
    assert devices["pm100"]["identity"]["sensor_serial"]
    modbus = [d["identity"] for d in devices.values() if d["protocol"] == "modbus-stage"]
    assert modbus and all({"vendor", "model", "serial", "firmware"} <= set(i) for i in modbus)
    r = run.readings()
    assert len(r) == run.meta["planned"]
    s = r[r["kind"] == "sample"]
    assert set(np.round(s["azimuth_deg"], 3)) == {0.0, 45.0}  # the Modbus drive turned
    assert np.ptp(s["elevation_deg"]) > 5.0  # the ESP's third axis lifted the detector
    beam, dark = r[r["kind"] == "beam"], r[r["kind"] == "dark"]
    assert beam["power_w"].min() > 1e-4 > 1e-7 > dark["power_w"].max()


def test_emulated_detector_sees_the_positions_real_stages_report(emulated_lab, tmp_path):
    cfg, endpoints = emulated_lab
    instrument = write_toml(tmp_path / "mixed.toml", pointed(cfg, endpoints))
    plan = write_toml(tmp_path / "plan.toml", PLAN)
    proc = gonio_cli("scan", plan, "--instrument", instrument, "--sim", "detector",
                     "--out", tmp_path / "runs", "--no-plot")
    assert proc.returncode == 0, proc.stderr
    run = open_run(run_dir_of(proc))
    assert run.meta["sim"] == ["detector"]
    assert run.meta["sessions"][0]["sim"] == ["pm100"]
    assert run.meta["sessions"][0]["endpoints"]["esp"] == endpoints["esp"][1]
    r = run.readings()
    beam, dark = r[r["kind"] == "beam"], r[r["kind"] == "dark"]
    # the in-process detector only knows where the stages are from what they reported
    assert beam["power_w"].min() > 1e-4 > 1e-7 > dark["power_w"].max()
    s = r[r["kind"] == "sample"]
    assert (s["power_w"] > dark["power_w"].max()).all()


def test_unknown_sim_name_is_one_clear_error(tmp_path):
    cfg = rehearsal_config()
    instrument = write_toml(tmp_path / "lab.toml", cfg)
    plan = write_toml(tmp_path / "plan.toml", PLAN)
    proc = gonio_cli("scan", plan, "--instrument", instrument, "--sim", "shutter",
                     "--out", tmp_path / "runs")
    assert proc.returncode == 2
    assert "--sim shutter: no such device or role" in proc.stderr
    assert "Traceback" not in proc.stderr and not (tmp_path / "runs").exists()
