"""An environment sensor in the instrument config (the emulated XY-MD02 on its own RTU line):
every reading line carries the room with its u, the run's record sums the lines up, an
aborted run resumes and checks clean, and a plan or config that says the room twice is one
clear error."""

import copy
import json
import math

import numpy as np
import pytest
from gonio_testkit import EXAMPLES, AbortAfter, fast_config, gonio_cli, write_plan, write_toml

from gonio.config import parse_config
from gonio.errors import ConfigError, PlanError
from gonio.plan import build_schedule, parse_plan
from gonio.record import run_record
from gonio.runner import new_scan, resume_scan
from gonio.store import open_run

ROOM_MAP = EXAMPLES / "registermaps" / "xy-md02.toml"
U_TEMPERATURE_C = 0.5 / math.sqrt(3.0)  # the XY-MD02 manual's +-0.5 degC
U_HUMIDITY_REL = 0.03 / math.sqrt(3.0)  # and +-3 %RH
DRIFT_C_PER_H = 30.0
SAMPLE = {"id": "room-glass", "kind": "hemisphere", "eta": 1.51, "lit_from": "air",
          "shape": "hemisphere", "diameter_mm": 25.4,
          "azimuth_reference": "sample azimuth 0: the holder's index mark points up"}
PLAN = {"name": "room", "sample": SAMPLE, "dark": {"every": 8}, "beam": {"every": 8}, "grid": [
    {"side": "reflection", "theta_i_deg": [0.0, 30.0],
     "theta_o_deg": {"start": -60.0, "stop": 60.0, "step": 10.0}, "skip_forbidden": True}]}
SENSOR = {"protocol": "modbus-environment", "transport": "rtu", "port": "/dev/ttyUSB3",
          "baudrate": 9600, "parity": "none", "unit": 1, "register_map": str(ROOM_MAP),
          "timeout_s": 0.5}


def room_config() -> dict:
    """The emulated Modbus bench with an XY-MD02 on a line of its own, in a room warming by
    DRIFT_C_PER_H (a smooth sample: no multiple-scattering tables to build)."""
    cfg = fast_config("sim-modbus")
    cfg["devices"]["room"] = dict(SENSOR)
    cfg["sim"]["sample"] = {"distribution": "beckmann", "alpha": 0.05}
    cfg["sim"]["room"] = {"temperature_c": 22.0, "humidity_rel": 0.40,
                          "temperature_drift_c_per_h": DRIFT_C_PER_H}
    return cfg


@pytest.fixture(scope="module")
def completed(tmp_path_factory):
    """A completed emulated run with the sensor: its directory."""
    folder = tmp_path_factory.mktemp("room")
    result = new_scan(write_plan(folder, PLAN, room_config()), sim=True, out=folder / "runs",
                      progress=False)
    assert result.outcome.status == "completed", result.outcome.reason
    return result.path


def test_every_reading_line_carries_the_room_read_beside_it(completed):
    rows = open_run(completed).rows()
    assert len(rows) > 20
    for row in rows:
        assert row["u_temperature_c"] == pytest.approx(U_TEMPERATURE_C, rel=1e-12)
        assert row["u_humidity_rel"] == pytest.approx(U_HUMIDITY_REL, rel=1e-12)
        assert row["humidity_rel"] == 0.4
        # the room at the reading's time on the bench's clock, in the sensor's 0.1 degC steps
        room = 22.0 + DRIFT_C_PER_H * row["t_s"] / 3600.0
        assert abs(row["temperature_c"] - room) <= 0.05 + 1e-9, row
        assert round(row["temperature_c"] * 10) == pytest.approx(row["temperature_c"] * 10)
    temperatures = [row["temperature_c"] for row in rows]
    assert max(temperatures) - min(temperatures) >= 0.2  # the drift shows


def test_the_records_environment_is_the_sensors_mean_with_its_spread(completed):
    run = open_run(completed)
    env = run_record(run)["environment"]
    t = np.array([row["temperature_c"] for row in run.rows()])
    assert env["temperature_c"] == pytest.approx(t.mean(), rel=1e-12)
    assert env["u_temperature_c"] == pytest.approx(
        math.hypot(U_TEMPERATURE_C, t.std(ddof=1)), rel=1e-12)
    assert env["humidity_rel"] == pytest.approx(0.4, rel=1e-12)
    assert env["u_humidity_rel"] == pytest.approx(U_HUMIDITY_REL, rel=1e-12)  # no spread
    assert env["notes"].startswith(f"environment sensor room: mean of {len(t)} readings")
    devices = run.meta["sessions"][0]["devices"]
    assert devices["room"]["protocol"] == "modbus-environment"
    assert devices["room"]["identity"] == {}  # the XY-MD02 reports none


def test_the_bird_export_states_the_sensors_environment(completed, tmp_path):
    out = tmp_path / "room.json"
    proc = gonio_cli("export", completed, "--format", "bird", "--out", out)
    assert proc.returncode == 0, proc.stderr
    env = run_record(open_run(completed))["environment"]
    stated = json.loads(out.read_text())["metadata"]["environment"]
    assert stated["temperature"]["value"] == pytest.approx(env["temperature_c"], rel=1e-12)
    assert stated["temperature"]["uncertainty"] == pytest.approx(env["u_temperature_c"],
                                                                 rel=1e-12)
    assert stated["relative_humidity"]["value"] == pytest.approx(40.0, rel=1e-12)  # in %
    assert stated["relative_humidity"]["uncertainty"] == pytest.approx(100 * U_HUMIDITY_REL,
                                                                       rel=1e-12)


def test_an_aborted_run_with_the_sensor_resumes_and_checks_clean(tmp_path):
    plan = write_plan(tmp_path, PLAN, room_config())
    first = new_scan(plan, sim=True, out=tmp_path / "runs", progress=False,
                     control=AbortAfter(9))
    assert first.outcome.status == "aborted" and first.outcome.done == 9
    second = resume_scan(first.path, progress=False)
    assert second.outcome.status == "completed", second.outcome.reason
    rows = open_run(first.path).rows()
    assert [row["index"] for row in rows] == list(range(len(rows)))
    assert all("temperature_c" in row and "humidity_rel" in row for row in rows)
    times = [row["t_s"] for row in rows]
    assert times == sorted(times)  # the resumed clock goes on, and the room with it
    proc = gonio_cli("check", first.path)
    assert proc.returncode == 0, proc.stdout + proc.stderr


def test_a_plan_environment_beside_a_sensor_is_refused_before_anything_opens(tmp_path):
    plan = {**PLAN, "environment": {"temperature_c": 21.5}}
    path = write_plan(tmp_path, plan, room_config())
    with pytest.raises(PlanError) as err:
        new_scan(path, sim=True, out=tmp_path / "runs", progress=False)
    assert str(err.value) == (
        f"{path}: [environment]: the instrument's environment sensor 'room' measures the room "
        "at every reading; state the environment in one place: remove [environment] from the "
        "plan, or the sensor from the config")
    assert not (tmp_path / "runs").exists() or not any((tmp_path / "runs").iterdir())
    # without the sensor the same plan's [environment] is the run's
    build_schedule(parse_plan(plan), parse_config(fast_config("sim-modbus")))


def test_a_second_sensor_is_one_config_error():
    cfg = room_config()
    cfg["devices"]["room2"] = {**SENSOR, "port": "/dev/ttyUSB4"}
    with pytest.raises(ConfigError) as err:
        parse_config(cfg)
    assert str(err.value) == ("config: [devices.room2]: a second environment sensor; the config "
                              "has 'room' already (one is read at every reading)")


def test_a_sensor_map_without_its_accuracy_is_refused(tmp_path):
    text = ROOM_MAP.read_text()
    bare = tmp_path / "bare.toml"
    bare.write_text(text.replace("temperature_half_width_c = 0.5\n", ""))
    cfg = copy.deepcopy(room_config())
    cfg["devices"]["room"]["register_map"] = str(bare)
    with pytest.raises(ConfigError) as err:
        parse_config(cfg)
    assert str(err.value) == (
        f"config: [devices.room] register_map: {bare} [specification] temperature_half_width_c: "
        "missing (the sensor's accuracy, a uniform +-a, gives each reading its uncertainty)")


def test_sim_room_is_checked_like_every_sim_table(tmp_path):
    cfg = room_config()
    cfg["sim"]["room"]["humidity_rel"] = 1.5
    path = write_plan(tmp_path, PLAN, cfg)
    with pytest.raises(ConfigError, match=r"\[sim.room\] humidity_rel: must be a number >= 0 "
                                          r"and <= 1, got 1.5"):
        new_scan(path, sim=True, out=tmp_path / "runs", progress=False)


def test_write_toml_keeps_the_sensor_table(tmp_path):
    # the config a run stores reads back with its sensor (resume parses it again)
    path = write_toml(tmp_path / "cfg.toml", room_config())
    assert parse_config(room_config(), path).environment == "room"
