"""Faults injected in the emulators during a 1,000-point scan: the run completes (retrying
what is safe to retry) or stops with a clear reason; no point is lost or duplicated."""

import os
import shutil
import tempfile
from pathlib import Path

import numpy as np
import pytest
from gonio_testkit import fast_config, write_toml

from gonio.config import parse_config
from gonio.plan import build_schedule, parse_plan
from gonio.runner import new_scan, resume_scan
from gonio.store import open_run

PLAN = {"name": "faults", "dark": {"every": 100}, "beam": {"every": 100}, "grid": [
    {"side": ["reflection", "transmission"], "theta_i_deg": [0.0, 20.0, 40.0, 60.0],
     "theta_o_deg": {"start": -80.0, "stop": 80.0, "num": 131}, "skip_forbidden": True}]}


@pytest.fixture
def fast_store(tmp_path):
    """A folder for run directories on tmpfs when there is one: tests about faults and
    throughput of the engine need not pay the disk's fsync (the kill tests do not use it)."""
    shm = Path("/dev/shm")
    if not (shm.is_dir() and os.access(shm, os.W_OK)):
        yield tmp_path
        return
    folder = Path(tempfile.mkdtemp(dir=shm, prefix="gonio-test-"))
    yield folder
    shutil.rmtree(folder, ignore_errors=True)


def write(tmp_path, cfg):
    write_toml(tmp_path / "instrument.toml", cfg)
    return write_toml(tmp_path / "plan.toml", {**PLAN, "instrument": "instrument.toml"})


def assert_contiguous_and_planned(run_dir, cfg, plan=PLAN):
    r = open_run(run_dir).readings()
    sched = build_schedule(parse_plan(plan), parse_config(cfg)).readings
    assert list(r["index"]) == list(range(len(r)))  # nothing lost, nothing twice
    np.testing.assert_array_equal(r["kind"], sched["kind"][: len(r)])
    for role in ("sample", "arm"):  # every reading was taken where the plan said
        np.testing.assert_allclose(r[f"{role}_deg"], sched[f"{role}_deg"][: len(r)], atol=0.01)
    return r, sched


@pytest.mark.parametrize("instrument, faults", [
    ("sim-serial", {"esp": {"drop_prob": 0.002, "corrupt_prob": 0.002, "stall_prob": 0.001},
                    "pm100": {"drop_prob": 0.003, "corrupt_prob": 0.003, "stall_prob": 0.002}}),
    ("sim-modbus", {"arm_drive": {"bad_crc_prob": 0.003, "stall_prob": 0.002},
                    "photodiode": {"bad_crc_prob": 0.005, "drop_prob": 0.002,
                                   "stall_prob": 0.002}}),
])
@pytest.mark.slow
def test_thousand_points_with_faults_complete(tmp_path, fast_store, instrument, faults):
    # short reply timeouts keep the stalls cheap; the detector's reply includes the bench's
    # physics, which a loaded machine can slow to tens of ms; the units on one Modbus link
    # (the drives' TCP server) share its timeout
    cfg = fast_config(instrument, faults=faults)
    for name, dev in cfg["devices"].items():
        dev["timeout_s"] = 0.5 if name in ("pm100", "photodiode") else 0.2
    result = new_scan(write(tmp_path, cfg), sim=True, out=fast_store, progress=False)
    r, sched = assert_contiguous_and_planned(result.path, cfg)
    assert len(sched) >= 1000
    meta = open_run(result.path).meta
    injected = meta["sessions"][-1]["faults_injected"]
    assert set(injected) == set(faults)
    if result.outcome.status == "completed":
        assert len(r) == len(sched)
        assert sum(sum(c.values()) for c in injected.values()) > 10  # faults did happen
    else:  # allowed, but only with a reason that names the reading and the device
        assert result.outcome.status == "failed"
        assert meta["reason"].startswith(f"reading {len(r)} ")
    assert meta["status"] == result.outcome.status


def test_disconnect_stops_cleanly_and_resume_finishes(tmp_path, fast_store):
    plan = {**PLAN, "grid": [{**PLAN["grid"][0], "theta_i_deg": [20.0]}]}  # ~260 readings
    cfg = fast_config("sim-serial", faults={"pm100": {"disconnect_after": 150}},
                      pm100={"timeout_s": 0.5})
    write_toml(tmp_path / "instrument.toml", cfg)
    path = write_toml(tmp_path / "plan.toml", {**plan, "instrument": "instrument.toml"})
    first = new_scan(path, sim=True, out=fast_store, progress=False)
    assert first.outcome.status == "failed"
    meta = open_run(first.path).meta
    assert "pm100" in meta["reason"] and "attempts" in meta["reason"]
    r, sched = assert_contiguous_and_planned(first.path, cfg, plan)
    assert 0 < len(r) < len(sched)
    # fresh emulators: the device "reconnected"; the run continues where it stopped
    second = resume_scan(first.path, progress=False)
    assert second.outcome.status == "completed"  # fewer replies left than disconnect_after
    r2, _ = assert_contiguous_and_planned(first.path, cfg, plan)
    assert len(r2) == len(sched)
    sessions = open_run(first.path).meta["sessions"]
    assert [s["status"] for s in sessions] == ["failed", "completed"]
    assert sessions[1]["first_index"] == len(r)
