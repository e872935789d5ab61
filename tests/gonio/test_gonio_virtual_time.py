"""An all-emulated run's times are the emulated bench's modelled time: under `--time-scale inf`
two runs of one plan and seed store the same t_s and readings, a drifting source included, and
`gonio calibrate build` gives them the same offsets; a run's t_s, instant or paced at a finite
time scale, is the virtual duration of its moves (axes together), settling, dwell and readings
(the PM100's 3 ms a sample, the Modbus photodiode's map's 1 ms); the live view's ETA reads such
t_s as virtual seconds.
"""

import json
import tomllib

import numpy as np
import pytest
from gonio_testkit import EXAMPLES, fast_config, gonio_cli, run_dir_of, write_plan

from gonio.plan import MOTION_ROLES, profile_seconds
from gonio.store import open_run
from gonio_watch.status import eta_s

PLAN = {"name": "timed", "averaging": 7, "dwell_s": 0.25, "dark": {"every": 6},
        "beam": {"every": 6}, "grid": [{"side": "reflection", "theta_i_deg": [10.0, 30.0],
                                        "theta_o_deg": {"start": -40.0, "stop": 40.0,
                                                        "step": 20.0},
                                        "skip_forbidden": True}]}
PM100_SAMPLE_S = 3e-3  # the PM100 manual: "1 sample takes approx. 3ms"
PHOTODIODE_SAMPLE_S = 1e-3  # examples/registermaps/photodiode-adc.toml's sample_s


def config() -> dict:
    """The fast sim-serial config with a PM100 timeout no reply misses under load (a query
    re-sent after a timeout is another reading, which takes its time too)."""
    return fast_config(pm100={"timeout_s": 10.0})


def scan(folder, plan: dict, cfg: dict, name: str, time_scale: str = "inf"):
    """`gonio scan --sim --time-scale X` of plan on cfg; the finished run."""
    path = write_plan(folder, plan, cfg, name=name)
    proc = gonio_cli("scan", path, "--sim", "--time-scale", time_scale, "--out", folder / name,
                     "--no-plot", "--no-progress", timeout=600.0)
    assert proc.returncode == 0, proc.stderr
    return open_run(run_dir_of(proc))


def drifting(cfg: dict) -> dict:
    """The config with a source that drifts 5 % over a minute of the run's clock."""
    cfg["sim"]["source"] = {**cfg["sim"].get("source", {}), "drift_fraction": 0.05,
                            "drift_period_s": 60.0}
    return cfg


def test_two_instant_runs_store_the_same_times_and_readings_and_calibrate_alike(tmp_path):
    plan = tomllib.loads((EXAMPLES / "plans" / "calib-angles.toml").read_text())
    cfg = drifting(config())
    runs = [scan(tmp_path, plan, cfg, name) for name in ("first", "second")]
    first, second = (run.readings() for run in runs)
    assert first["t_s"][-1] > 60.0  # the drift has gone round
    for field in first.dtype.names:
        np.testing.assert_array_equal(first[field], second[field], err_msg=field)
    offsets = []
    for run in runs:
        out = tmp_path / f"{run.path.name}-cal.json"
        # --force: the drift, fast on purpose, leaves more than the fit's noise (a refusal)
        proc = gonio_cli("calibrate", "build", run.path, "--out", out, "--force",
                         timeout=600.0)
        assert proc.returncode == 0, proc.stderr
        angles = json.loads(out.read_text())["angles"]
        offsets.append((angles["sample_offset_deg"], angles["arm_offset_deg"]))
    assert offsets[0] == offsets[1]


def virtual_duration(readings: np.ndarray, cfg: dict, plan: dict, sample_s: float
                     ) -> np.ndarray:
    """When each reading ends on the virtual clock: from the stages' power-up positions, each
    row's moves (the axes together: the slowest), the moved axes' longest settling, the
    plan's dwell and the reading's averaged samples (sample_s each)."""
    axes = cfg["axes"]
    where = {role: min(max(0.0, ax["limits_deg"][0]), ax["limits_deg"][1])
             for role, ax in axes.items()}
    commanded: dict = dict.fromkeys(axes)
    t, ends = 0.0, []
    for row in readings:
        moved = [r for r in axes if r in MOTION_ROLES and commanded[r] != row[f"{r}_deg"]]
        t += max((profile_seconds(abs(row[f"{r}_deg"] - where[r]), axes[r]["speed_deg_s"],
                                  axes[r]["accel_deg_s2"]) for r in moved), default=0.0)
        t += max((axes[r]["settle_s"] for r in moved), default=0.0) + plan["dwell_s"]
        t += plan["averaging"] * sample_s
        for r in moved:
            where[r] = commanded[r] = float(row[f"{r}_deg"])
        ends.append(t)
    return np.array(ends)


@pytest.mark.parametrize(("name", "sample_s", "time_scale"), [
    ("sim-serial", PM100_SAMPLE_S, "inf"), ("sim-modbus", PHOTODIODE_SAMPLE_S, "inf"),
    ("sim-serial", PM100_SAMPLE_S, "200"), ("sim-modbus", PHOTODIODE_SAMPLE_S, "200")])
def test_a_runs_times_are_its_virtual_duration_at_any_time_scale(tmp_path, name, sample_s,
                                                                  time_scale):
    """At a finite time scale the devices pace real time, but t_s counts only what they were
    asked to do, so it is the same as an instant run's, whatever the machine's load."""
    cfg = config() if name == "sim-serial" else fast_config(name)
    got = scan(tmp_path, PLAN, cfg, "timed", time_scale).readings()
    assert len(got) > 10 and {"dark", "beam"} <= set(got["kind"])
    np.testing.assert_allclose(got["t_s"], virtual_duration(got, cfg, PLAN, sample_s),
                               rtol=1e-9)


def test_the_live_views_eta_reads_virtual_seconds_at_the_runs_time_scale():
    session = {"start_utc": "2026-01-01T00:00:00+00:00", "clock": "virtual",
               "clock_start_s": 100.0}
    rows = [{"t_s": 100.0 + 2.0 * k} for k in range(5)]  # 2 virtual s a reading
    meta = {"sessions": [session], "t0_epoch": 0.0, "estimate_s": 30.0, "time_scale": 10.0}
    assert eta_s(meta, rows, 15) == (10 * 0.2, "median of the last 5 readings")
    assert eta_s({**meta, "time_scale": "inf"}, rows, 15) == (20.0, "the plan's estimate")
