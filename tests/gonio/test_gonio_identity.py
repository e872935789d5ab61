"""Each session of a run records every device by the identity it reported (ESP VE?, PM100
*IDN? and sensor head, Modbus 43/14 and [identity] registers); a resume on other hardware
records the other identity and warns about it; `gonio scan PLAN --resume RUN` takes a PLAN
only if it is the run's own; `gonio emulate --time-scale X` runs the emulated clock X times
real time."""

import os
import signal
import subprocess
import sys
import time

import pytest
from gonio_testkit import (
    ROOT,
    AbortAfter,
    dump_toml,
    emulating,
    fast_config,
    gonio_cli,
    one_line_error,
    pointed,
    run_dir_of,
    write_plan,
    write_toml,
)

from drivers.esp import EspController
from gonio.runner import new_scan
from gonio.store import open_run
from sim.devices.modbus_server import FIRMWARE
from sim.devices.motion import profile_times

PLAN = {"name": "identity", "averaging": 2, "beam": {"every": 2}, "grid": [
    {"side": "reflection", "theta_i_deg": [20.0], "theta_o_deg": [10.0, 30.0, 50.0]}]}


def aborted_run(tmp_path, cfg):
    """An emulated run of PLAN on cfg, aborted at once: (plan file, run directory)."""
    plan = write_plan(tmp_path, PLAN, cfg)
    result = new_scan(plan, sim=True, out=tmp_path / "runs", progress=False,
                      control=AbortAfter(0))
    assert result.outcome.status == "aborted" and result.outcome.done < 4
    return plan, result.path


@pytest.mark.parametrize("instrument", ["sim-serial", "sim-modbus"])
def test_meta_names_every_device_by_its_identity(tmp_path, instrument):
    cfg = fast_config(instrument)
    plan = write_plan(tmp_path, PLAN, cfg)
    proc = gonio_cli("scan", plan, "--sim", "--time-scale", "inf", "--out", tmp_path / "runs",
                     "--no-plot", "--no-progress")
    assert proc.returncode == 0, proc.stderr
    session = open_run(run_dir_of(proc)).meta["sessions"][0]
    devices = session["devices"]
    assert set(devices) == set(cfg["devices"])
    for name, record in devices.items():
        assert record["protocol"] == cfg["devices"][name]["protocol"]
        assert record["endpoint"] == session["endpoints"][name]
        assert "identity_note" not in record
    if instrument == "sim-serial":
        assert devices["esp"]["identity"] == {"version": "ESP301 Version 3.0.2 (emulated)"}
        pm = devices["pm100"]["identity"]
        assert pm["idn"].startswith("Thorlabs,PM100D,")
        assert (pm["sensor_name"], pm["sensor_serial"]) == ("S121C", "EMU00001")
        assert pm["sensor_calibration"] and pm["sensor_type"] == "1"
        return
    seed = cfg["sim"]["seed"]
    for index, (name, vendor, model) in enumerate([
            ("sample_drive", "Example Motion Co", "stepper-drive"),
            ("arm_drive", "Example Motion Co", "stepper-drive"),
            ("photodiode", "Example Photonics", "photodiode-adc")]):
        record = devices[name]
        assert (record["transport"], record["unit"]) == (cfg["devices"][name]["transport"],
                                                         cfg["devices"][name]["unit"])
        assert record["identity"] == {"vendor": vendor, "model": model, "firmware": FIRMWARE,
                                      "serial": f"SIM{seed + index:05d}"}


def test_resume_with_its_plan_on_other_hardware_records_that_hardware(tmp_path):
    """A run on one bench (`gonio emulate`) resumed with the same plan (reformatted, with
    comments) on another, at other endpoints and with other serial numbers: the second
    session records the endpoint change and the other identities, and the scan warns."""
    cfg = fast_config("sim-modbus")
    with emulating(write_toml(tmp_path / "bench1.toml", cfg)) as endpoints:
        first = pointed(cfg, endpoints)
        plan = write_plan(tmp_path, PLAN, first)
        result = new_scan(plan, out=tmp_path / "runs", progress=False, control=AbortAfter(1))
    run_dir = result.path
    assert result.outcome.status == "aborted"
    same = tmp_path / "same.toml"
    text = dump_toml(dict(reversed({**PLAN, "instrument": "plan-instrument.toml"}.items())))
    same.write_text("# the plan again, written by hand\n\n" + text.replace("\n[", "\n# a table\n["))
    bench2 = write_toml(tmp_path / "bench2.toml", {**cfg, "sim": {**cfg["sim"], "seed": 40}})
    with emulating(bench2) as endpoints:
        second = pointed(cfg, endpoints)
        other = write_toml(tmp_path / "other.toml", second)
        proc = gonio_cli("scan", same, "--resume", run_dir, "--instrument", other, "--no-plot",
                         "--no-progress")
    assert proc.returncode == 0, proc.stderr
    assert run_dir_of(proc) == run_dir
    assert "warning: device 'photodiode' reports another identity" in proc.stderr
    run = open_run(run_dir)
    assert run.meta["status"] == "completed" and len(run) == run.meta["planned"]
    session = run.meta["sessions"][-1]
    moved = {f"devices.{name}.{key}": {"from": dev.get(key), "to": second["devices"][name][key]}
             for name, dev in first["devices"].items() for key in ("port", "host", "tcp_port")
             if dev.get(key) != second["devices"][name].get(key)}
    assert session.get("endpoint_changes", {}) == moved
    assert set(session["identity_changes"]) == set(cfg["devices"])
    first, second = (s["devices"] for s in run.meta["sessions"])
    for name in cfg["devices"]:
        before, after = first[name]["identity"], second[name]["identity"]
        assert before["model"] == after["model"] and before["serial"] != after["serial"]
    assert second["photodiode"]["identity"]["serial"] == "SIM00042"


def test_resume_with_another_plan_is_refused_naming_the_keys(tmp_path):
    cfg = fast_config("sim-serial")
    plan, run_dir = aborted_run(tmp_path, cfg)
    stored = open_run(run_dir)
    changed = write_toml(tmp_path / "changed.toml", {
        **PLAN, "instrument": "plan-instrument.toml", "averaging": 8,
        "beam": {"every": 5}, "dwell_s": 0.1})
    proc = gonio_cli("scan", changed, "--resume", run_dir, "--no-plot")
    assert proc.returncode == 2, proc.stderr
    line = one_line_error(proc.stderr)
    assert f"{changed}: not the plan {run_dir} was started with" in line
    assert "(differs in averaging, beam.every, dwell_s)" in line
    after = open_run(run_dir)
    assert len(after) == len(stored) and after.meta["sessions"] == stored.meta["sessions"]
    matching = gonio_cli("scan", plan, "--resume", run_dir, "--no-plot", "--no-progress")
    assert matching.returncode == 0, matching.stderr  # its own file, as written


def test_emulate_time_scale_runs_moves_that_much_faster(tmp_path):
    cfg = fast_config("sim-serial", time_scale=1.0)  # real time in the file
    path = write_toml(tmp_path / "bench.toml", cfg)
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen([sys.executable, "-m", "gonio_cli", "emulate", str(path),
                             "--time-scale", "10"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env)
    try:
        ports = dict(proc.stdout.readline().split()[::2] for _ in cfg["devices"])
        with EspController(ports["esp"], timeout_s=1.0) as esp:
            axis = esp.axis(1)
            t_acc, t_cruise, t_dec = profile_times(60.0, 20.0, 80.0)
            virtual_s = t_acc + t_cruise + t_dec  # 3.25 s in real time
            t0 = time.monotonic()
            axis.move_to(60.0)
            assert axis.wait(10.0) == pytest.approx(60.0, abs=1e-3)
            elapsed = time.monotonic() - t0
    finally:
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=20)
    assert proc.returncode == 0, err
    assert virtual_s / 10 * 0.9 < elapsed < virtual_s / 3, elapsed
