"""Detector ranges in plans: parsing and errors that name the field, how each reading's range is
resolved (grid/point, plan, [dark]/[beam], instrument), checks against the detector before any
motion, and scans on the emulated PM100 and Modbus amplifier reading on the planned ranges."""

import numpy as np
import pytest
from gonio_testkit import fast_config, write_plan
from hypothesis import given, settings
from hypothesis import strategies as st

from gonio.config import parse_config
from gonio.errors import PlanError
from gonio.plan import AUTO_RANGE, build_schedule, parse_plan
from gonio.runner import new_scan
from gonio.store import open_run

SERIAL = parse_config(fast_config("sim-serial"))
MODBUS = parse_config(fast_config("sim-modbus"))
FIXED = parse_config({**fast_config("sim-serial"),
                      "detector": {**fast_config("sim-serial")["detector"], "range": 1e-6}})


def plan_dict(grid_range=None, **top) -> dict:
    grid = {"side": "transmission", "theta_i_deg": 0.0, "theta_o_deg": [0.0, 10.0, 20.0]}
    if grid_range is not None:
        grid["range"] = grid_range
    return {"order": "as-written", "grid": [grid], "dark": {"every": 3}, "beam": {"every": 6},
            **top}


def test_plan_without_ranges_keeps_the_instruments_range():
    for cfg, expected in ((SERIAL, AUTO_RANGE), (FIXED, 1e-6)):
        r = build_schedule(parse_plan(plan_dict()), cfg).readings
        assert set(r["range_w"]) == {expected}
        # one dark reading per slot, as before ranges existed
        assert list(r["kind"][:2]) == ["dark", "beam"] and (r["kind"] == "dark").sum() == 2


def test_grid_steps_through_its_ranges_at_each_point():
    plan = parse_plan(plan_dict([1e-7, 1e-6, "auto"], beam={"every": 6, "range": "auto"}))
    r = build_schedule(plan, FIXED).readings
    samples = r[r["kind"] == "sample"]
    # range is the innermost grid coordinate: every range read at a position before moving on
    assert list(samples["range_w"]) == [1e-7, 1e-6, AUTO_RANGE] * 3
    assert np.all(samples["arm_deg"][0:3] == samples["arm_deg"][0])
    # a dark slot reads every range the samples use; beam readings their own [beam] range
    first_darks = r["range_w"][:3][r["kind"][:3] == "dark"]
    assert sorted(first_darks) == [AUTO_RANGE, 1e-7, 1e-6]
    assert set(r["range_w"][r["kind"] == "beam"]) == {AUTO_RANGE}


def test_plan_point_and_dark_ranges_override_in_order():
    plan = parse_plan({"range": 1e-5, "order": "as-written",
                       "point": [{"side": "transmission", "theta_i_deg": 0.0, "theta_o_deg": 5.0,
                                  "range": 1e-7},
                                 {"side": "transmission", "theta_i_deg": 0.0, "theta_o_deg": 9.0}],
                       "dark": {"every": 2, "range": "auto"}, "beam": {"every": 2}})
    r = build_schedule(plan, FIXED).readings
    by_kind = {k: list(r["range_w"][r["kind"] == k]) for k in ("sample", "dark", "beam")}
    assert by_kind["sample"] == [1e-7, 1e-5]  # the point's, else the plan's (not the config's)
    assert set(by_kind["dark"]) == {AUTO_RANGE} and set(by_kind["beam"]) == {1e-5}


@pytest.mark.parametrize("where,value,message", [
    ("top", -1e-6, "plan: range: must be \"auto\" or a fixed full scale in W > 0; got -1e-06"),
    ("top", "manual", "plan: range: must be \"auto\" or a fixed full scale in W > 0; got 'manual'"),
    ("top", [1e-6], "plan: range: must be \"auto\" or a fixed full scale in W > 0; got [1e-06]"),
    ("grid", [1e-6, 0.0], "plan: [grid[0]] range: must be \"auto\" or a fixed full scale in W > 0 "
                          "or a list of them; got 0.0"),
    ("dark", True, "plan: [dark] range: must be \"auto\""),
])
def test_bad_range_is_one_error_naming_the_field(where, value, message):
    raw = plan_dict()
    if where == "top":
        raw["range"] = value
    elif where == "grid":
        raw["grid"][0]["range"] = value
    else:
        raw["dark"]["range"] = value
    with pytest.raises(PlanError) as err:
        parse_plan(raw)
    assert message in str(err.value)


def test_range_beyond_a_modbus_amplifier_is_refused_before_any_motion():
    with pytest.raises(PlanError, match=r"grid\[0\] point: range 0.1 W is above the largest "
                                        r"range 0.01 W of the detector"):
        build_schedule(parse_plan(plan_dict([1e-6, 0.1])), MODBUS)
    with pytest.raises(PlanError, match=r"\[beam\]: range 1 W is above"):
        build_schedule(parse_plan(plan_dict(beam={"every": 6, "range": 1.0})), MODBUS)


@pytest.mark.parametrize("instrument", ["sim-serial", "sim-modbus"])
def test_scan_reads_each_reading_on_its_planned_range(instrument, tmp_path):
    # the emulated PM100 (SENS:POW:RANG) and Modbus amplifier (gain range register) read on
    # the range the schedule asks for; the run records the range of every reading
    raw = plan_dict([1e-5, 1e-4, "auto"], beam={"every": 6, "range": "auto"})
    plan = write_plan(tmp_path, raw, fast_config(instrument))
    result = new_scan(plan, None, sim=True, out=tmp_path / "runs", progress=False)
    assert result.outcome.status == "completed", result.outcome
    r = open_run(result.path).readings()
    sched = build_schedule(parse_plan(raw), parse_config(fast_config(instrument))).readings
    fixed = sched["range_w"] != AUTO_RANGE
    np.testing.assert_array_equal(r["range_w"][fixed], sched["range_w"][fixed])
    # autoranged sample readings pick their own (most sensitive unsaturated) range
    auto = (sched["kind"] == "sample") & ~fixed
    assert np.all(r["range_w"][auto] <= 1e-2) and not r["saturated"][auto].any()
    # the same positions read on 1e-5 and 1e-4 W agree within the 1e-4 W range's read noise
    # (no gain errors on this bench; readings that saturate 1e-5 W left out)
    pick = {rw: (sched["kind"] == "sample") & (sched["range_w"] == rw) for rw in (1e-5, 1e-4)}
    unsaturated = ~r["saturated"][pick[1e-5]]
    assert unsaturated.sum() >= 2
    np.testing.assert_allclose(r["power_w"][pick[1e-5]][unsaturated],
                               r["power_w"][pick[1e-4]][unsaturated], rtol=0.01, atol=1e-7)


def test_scan_with_a_range_the_pm100_lacks_stops_before_moving(tmp_path):
    # the PM100's sensor tops out at 10 mW; the config cannot know that, the device can
    cfg = fast_config("sim-serial")
    plan = write_plan(tmp_path, plan_dict([1e-6, 0.5]), cfg)
    result = new_scan(plan, None, sim=True, out=tmp_path / "runs", progress=False)
    assert result.outcome.status == "failed"
    assert "the plan's detector range 0.5 W: the detector refuses it" in result.outcome.reason
    assert result.outcome.done == 0


@settings(max_examples=60, deadline=None, derandomize=True)
@given(st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-10, 10),
                 st.text(max_size=8), st.booleans()))
def test_any_range_value_is_taken_exactly_or_refused_by_name(value):
    raw = plan_dict(value)
    valid = value == "auto" or (not isinstance(value, bool | str) and np.isfinite(value)
                                and value > 0)
    if not valid:
        with pytest.raises(PlanError, match=r"\[grid\[0\]\] range: must be"):
            parse_plan(raw)
        return
    r = build_schedule(parse_plan(raw), SERIAL).readings
    expected = AUTO_RANGE if value == "auto" else float(value)
    assert set(r["range_w"][r["kind"] == "sample"]) == {expected}
