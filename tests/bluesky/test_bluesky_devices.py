"""gonio's devices under Bluesky's RunEngine on the emulated serial bench (ESP301 stages and a
PM100 meter on real ptys, instant motion): Bluesky's own scan moves the arm and reads light,
a gonio plan runs its schedule in order, and a driver's error reaches the RunEngine naming
the device."""

from __future__ import annotations

import threading

import numpy as np
import pytest

pytest.importorskip("ophyd_async", reason="gonio.bluesky needs ophyd-async (the bluesky extra)")

import bluesky.plan_stubs as bps  # noqa: E402
import bluesky.plans as bp  # noqa: E402
from bluesky import RunEngine  # noqa: E402
from bluesky_testkit import small_plan, validated  # noqa: E402
from gonio_testkit import fast_config, write_plan, write_toml  # noqa: E402

from gonio.bluesky import DeviceFailure, devices, plan  # noqa: E402
from gonio.config import load_config  # noqa: E402
from gonio.plan import build_schedule, load_plan  # noqa: E402


@pytest.fixture(scope="module")
def bench(tmp_path_factory):
    folder = tmp_path_factory.mktemp("bluesky")
    plan_path = small_plan(folder)
    RE = RunEngine()
    docs: list = []
    RE.subscribe(lambda name, doc: docs.append((name, doc)))
    with devices(folder / "plan-instrument.toml", sim=True,
                 sample=load_plan(plan_path).raw["sample"]) as d:
        yield RE, d, docs, plan_path


def run_documents(RE, docs, plan_gen):
    """Run a plan; the documents of that run alone."""
    docs.clear()
    RE(plan_gen)
    return validated(list(docs))


def events(docs, stream="primary"):
    descriptors = {doc["uid"] for name, doc in docs
                   if name == "descriptor" and doc["name"] == stream}
    return [doc for name, doc in docs if name == "event" and doc["descriptor"] in descriptors]


def test_a_bluesky_scan_moves_the_arm_and_reads_light(bench):
    RE, d, docs, _ = bench
    RE(bps.mv(d.sample, 0.0))
    scan = events(run_documents(RE, docs, bp.scan([d.detector], d.arm, 10, 80, 8)))
    arm = np.array([e["data"]["arm"] for e in scan])
    power = np.array([e["data"]["detector-power_w"] for e in scan])
    np.testing.assert_allclose(arm, np.linspace(10, 80, 8), atol=1e-3)
    assert abs(d.instrument.axes["arm"].position() - 80.0) < 1e-3  # the emulated stage moved
    # dark: sample edge-on, the arm looking away from everything
    RE(bps.mv(d.sample, 90.0, d.arm, 90.0))
    dark = events(run_documents(RE, docs, bp.count([d.detector], 3)))
    dark_w = max(abs(e["data"]["detector-power_w"]) for e in dark)
    assert len(power) == 8 and (power > 5 * dark_w).all(), (power, dark_w)
    assert not any(e["data"]["detector-saturated"] for e in scan)


def test_a_gonio_plan_runs_its_schedule_in_order(bench):
    RE, d, docs, plan_path = bench
    sched = build_schedule(load_plan(plan_path), load_config(plan_path.parent /
                                                               "plan-instrument.toml"))
    rows = sched.readings
    docs_run = run_documents(RE, docs, plan(plan_path, d))
    got = events(docs_run)
    assert [e["seq_num"] for e in got] == list(range(1, len(rows) + 1))
    assert [e["data"]["schedule-index"] for e in got] == rows["index"].tolist()
    assert [e["data"]["schedule-kind"] for e in got] == rows["kind"].tolist()
    assert {"dark", "beam", "sample"} <= set(rows["kind"])
    for role in ("sample", "arm"):
        np.testing.assert_allclose([e["data"][role] for e in got], rows[f"{role}_deg"],
                                   atol=1e-3)
    fixed = rows["range_w"] > 0  # dark and beam on the plan's fixed ranges
    np.testing.assert_allclose(np.array([e["data"]["detector-range_w"] for e in got])[fixed],
                               rows["range_w"][fixed])
    start = docs_run[0][1]
    assert start["gonio_plan"] == "bluesky-small" and start["num_points"] == len(rows)
    assert docs_run[-1][0] == "stop" and docs_run[-1][1]["exit_status"] == "success"


def device_failure(RE, plan_gen) -> DeviceFailure:
    """The DeviceFailure a plan ends with, from within what Bluesky wraps it in."""
    with pytest.raises(Exception) as raised:  # noqa: B017  (the wrapper is Bluesky's own)
        RE(plan_gen)
    failure = raised.value
    while failure is not None and not isinstance(failure, DeviceFailure):
        failure = failure.__cause__ or failure.__context__
    assert failure is not None, repr(raised.value)
    return failure


def test_a_device_error_reaches_the_run_engine_naming_the_device(bench):
    RE, d, _, _ = bench
    failure = device_failure(RE, bps.mv(d.detector.range_setting, 0.37))  # no such PM100 range
    assert failure.device == "detector" and str(failure).startswith("detector: setting the range")
    assert "pm100" in str(failure)  # and the driver's own device name


def test_a_lost_port_reaches_the_run_engine_naming_the_axis(tmp_path):
    RE = RunEngine()
    with devices(write_toml(tmp_path / "instrument.toml", fast_config()), sim=True) as d:
        d.instrument.axes["arm"].controller.close()  # the ESP's port is gone
        failure = device_failure(RE, bps.mv(d.arm, 120.0))
    assert failure.device == "arm" and str(failure).startswith("arm: ")
    assert "esp" in str(failure).lower(), str(failure)


def test_moves_the_limits_or_the_source_forbid_are_refused(bench):
    RE, d, _, _ = bench
    RE(bps.mv(d.arm, 90.0))
    for target, why in ((400.0, "outside its limits"), (3.0, "outside its limits")):
        with pytest.raises(Exception, match=why):  # noqa: B017
            RE(bps.mv(d.arm, target))
    assert abs(d.instrument.axes["arm"].position() - 90.0) < 1e-3
    with pytest.raises(AttributeError, match="no 'elevation' axis"):
        _ = d.elevation


def test_a_pause_mid_plan_replays_the_row_from_its_checkpoint(bench):
    # A pause (as a suspender) rewinds to the last checkpoint: the row under way is measured
    # again on resume, and every row is still read exactly once, in order.
    from bluesky.utils import RunEngineInterrupted

    RE, d, docs, plan_path = bench
    docs.clear()
    paused = []

    def pause_after_third_event(name, doc):
        if name == "event" and doc["seq_num"] == 3 and not paused:
            paused.append(True)  # from another thread, as a suspender or Ctrl-C would
            threading.Thread(target=RE.request_pause, kwargs={"defer": False}).start()

    token = RE.subscribe(pause_after_third_event)
    try:
        with pytest.raises(RunEngineInterrupted):
            RE(plan(plan_path, d))
        before = len(events(list(docs)))
        RE.resume()
    finally:
        RE.unsubscribe(token)
    got = events(validated(list(docs)))
    rows = build_schedule(load_plan(plan_path), d.config).readings
    assert paused and 3 <= before < len(rows)
    assert [e["data"]["schedule-index"] for e in got] == rows["index"].tolist()


def test_a_plan_given_to_devices_has_its_tables_built_before_the_first_move(tmp_path,
                                                                            monkeypatch):
    # as gonio scan --sim: the schedule's multiple-scattering tables are walked before the
    # RunEngine moves anything, none inside a detector's reply
    monkeypatch.setenv("GONIO_CACHE_DIR", str(tmp_path / "cache"))
    cfg = fast_config(pm100={"timeout_s": 10.0})
    cfg["sim"]["sample"] = {"distribution": "ggx", "alpha": 0.3319, "ms_walks": 1024,
                            "multiple_scattering": True}
    plan_path = write_plan(tmp_path, {"name": "tabulated", "grid": [
        {"theta_i_deg": [35.0], "theta_o_deg": [-50.0, 20.0, 50.0]}]}, cfg)
    RE = RunEngine()
    with devices(tmp_path / "plan-instrument.toml", sim=True, plan=plan_path) as d:
        before = d.emulation.bench.tables_record()
        assert before["walked"] == before["planes"] > 0
        RE(plan(plan_path, d))
        assert d.emulation.bench.tables_record()["in_readings"] == 0


def test_a_plans_dwell_passes_on_the_emulated_benchs_virtual_clock(tmp_path):
    # under --time-scale inf a dwell takes no real time but is counted on the run's clock
    plan_path = write_plan(tmp_path, {"name": "dwell", "dwell_s": 60.0, "grid": [
        {"theta_i_deg": [10.0], "theta_o_deg": [30.0, 50.0]}]}, fast_config())
    RE = RunEngine()
    with devices(tmp_path / "plan-instrument.toml", sim=True) as d:
        start = d.clock.now()
        RE(plan(plan_path, d))
        rows = len(build_schedule(load_plan(plan_path), d.config).readings)
        assert d.clock.now() - start >= 60.0 * rows
