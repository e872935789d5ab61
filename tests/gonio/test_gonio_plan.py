"""Plans: parsing, validation errors that name the point, ordering and the duration estimate
(checked against the emulators' own trapezoidal-profile axis)."""

import math

import numpy as np
import pytest
from gonio_testkit import EXAMPLES, fast_config
from hypothesis import given, settings
from hypothesis import strategies as st

from gonio.config import load_config, parse_config
from gonio.errors import PlanError
from gonio.plan import (
    MOTION_ROLES,
    build_schedule,
    load_plan,
    parse_plan,
    positions,
    serpentine,
)
from sim.devices.motion import TrapezoidAxis, VirtualClock

SERIAL = parse_config(fast_config("sim-serial"))
OOP = parse_config(fast_config("sim-serial", elevation=True))
NO_DARK = parse_config({k: v for k, v in fast_config().items() if k != "dark"})


def grid(**kw):
    return {"grid": [{"side": "reflection", "theta_i_deg": [30.0],
                      "theta_o_deg": [10.0, 20.0], **kw}]}


def test_demo_plan_schedule():
    plan = load_plan(EXAMPLES / "plans" / "demo.toml")
    assert plan.instrument == (EXAMPLES / "instruments" / "sim-serial.toml").resolve()
    sched = build_schedule(plan, load_config(plan.instrument))
    r = sched.readings
    assert list(r["index"]) == list(range(len(r)))
    samples = r[r["kind"] == "sample"]
    assert len(samples) == len(plan.points) - sched.skipped == 58
    assert sched.skipped == 2  # theta_o = -theta_i looks into the source
    # a dark and a beam reading first, after every 10 sample points, and at the end
    kinds = list(r["kind"])
    assert kinds[:2] == ["dark", "beam"] and kinds[-2:] == ["dark", "beam"]
    n_sample = np.cumsum(r["kind"] == "sample")
    extra = r["kind"] != "sample"
    assert set(n_sample[extra]) == {0, 10, 20, 30, 40, 50, 58}
    assert sched.estimate_s < sched.naive_estimate_s
    # every point measured exactly once
    assert sorted(samples["point"]) == sorted(set(samples["point"]))
    # whole names: a side for each sample reading, none for the others
    assert set(samples["side"]) == {"reflection", "transmission"} and set(r["side"][extra]) == {""}


def test_demo_plan_runs_on_the_lab_bench_less_what_its_table_post_hides():
    """A lab's rehearsal has a short plan that runs: on lab.toml (arm 268-276 deg forbidden)
    the demo drops the one more point the post hides, and nothing it keeps moves into it."""
    plan = load_plan(EXAMPLES / "plans" / "demo.toml")
    cfg = load_config(EXAMPLES / "instruments" / "lab.toml")
    sched = build_schedule(plan, cfg)
    assert sched.skipped == 3
    (low, high), = cfg.arm_forbidden_deg
    assert not np.any((sched.readings["arm_deg"] >= low) & (sched.readings["arm_deg"] <= high))


def test_schedule_is_deterministic():
    plan = load_plan(EXAMPLES / "plans" / "demo.toml")
    cfg = load_config(plan.instrument)
    a, b = build_schedule(plan, cfg), build_schedule(plan, cfg)
    for name in a.readings.dtype.names:  # NaN-aware (dark/beam have no plan angles)
        np.testing.assert_array_equal(a.readings[name], b.readings[name])


def independent_estimate(targets, cfg, per_read):
    """Move time from the emulators' TrapezoidAxis (axes together) + settle + per reading."""
    total = 0.0
    prev = targets[0]
    for t in targets:
        moves, settle = [0.0], [0.0]
        for j, role in enumerate(MOTION_ROLES):
            if role in cfg.axes and t[j] != prev[j]:
                ax = cfg.axes[role]
                axis = TrapezoidAxis(VirtualClock(0.0), ax.speed_deg_s, ax.accel_deg_s2)
                moves.append(axis.duration(t[j] - prev[j]))
                settle.append(ax.settle_s)
        total += max(moves) + max(settle) + per_read
        prev = t
    return total


@pytest.mark.parametrize("cfg", [SERIAL, OOP], ids=["in-plane", "out-of-plane"])
def test_estimate_matches_trapezoid_axis(cfg):
    raw = grid(theta_i_deg=[0.0, 20.0, 45.0], theta_o_deg={"start": 10, "stop": 70, "step": 15},
               phi_o_deg=[0.0, 20.0] if "elevation" in cfg.axes else [0.0])
    plan = parse_plan({**raw, "dwell_s": 0.5, "averaging": 3})
    sched = build_schedule(plan, cfg)
    per_read = 0.5 + 0.02 + 0.003 * 3
    expected = independent_estimate(positions(sched.readings), cfg, per_read)
    assert math.isclose(sched.estimate_s, expected, rel_tol=1e-9)


@settings(max_examples=40, deadline=None)
@given(ti=st.lists(st.sampled_from([-40.0, -10.0, 0.0, 15.0, 30.0, 60.0]), min_size=1,
                   max_size=4, unique=True),
       to=st.lists(st.floats(-85.0, 85.0), min_size=1, max_size=8, unique=True),
       repeats=st.integers(1, 3))
def test_optimal_order_never_slower_than_written(ti, to, repeats):
    raw = {"repeats": repeats, "grid": [{"side": ["reflection", "transmission"],
                                         "theta_i_deg": ti, "theta_o_deg": to,
                                         "skip_forbidden": True}]}
    try:
        sched = build_schedule(parse_plan(raw), SERIAL)
    except PlanError as exc:
        assert "forbidden zone" in str(exc) or "sweep" in str(exc)
        return
    assert sched.estimate_s <= sched.naive_estimate_s + 1e-9
    samples = sched.readings[sched.readings["kind"] == "sample"]
    kept = len(parse_plan(raw).points) - sched.skipped
    assert len(samples) == kept * repeats
    for r in range(repeats):  # each pass has each kept point once
        assert len(set(samples["point"][samples["repeat"] == r])) == kept


def test_serpentine_alternates_inner_direction():
    outer = np.repeat([0.0, 1.0, 2.0], 4)
    inner = np.tile([3.0, 1.0, 4.0, 2.0], 3)
    order = serpentine(np.stack([outer, inner], axis=1), (0, 1))
    np.testing.assert_array_equal(inner[order], [1, 2, 3, 4, 4, 3, 2, 1, 1, 2, 3, 4])
    np.testing.assert_array_equal(outer[order], outer)


@pytest.mark.parametrize("raw, cfg, message", [
    (grid(theta_o_deg=[-30.0]), SERIAL, "grid[0] point (side=reflection, theta_i=30, "
                                        "theta_o=-30, phi_o=0, sample_azimuth=0): detector 0 deg"),
    (grid(phi_o_deg=[30.0]), SERIAL, "needs a 'elevation' axis"),
    (grid(sample_azimuth_deg=[45.0]), SERIAL, "needs a 'azimuth' axis"),
    (grid(theta_i_deg=[80.0], theta_o_deg=[85.0], phi_o_deg=[90.0]), OOP,
     "elevation at 85 deg outside travel [-60, 60]"),
    ({"point": [{"theta_i_deg": 10.0, "theta_o_deg": 10.0, "sidee": "reflection"}]}, SERIAL,
     "[point[0]]: unknown key 'sidee'"),
    ({**grid(), "dark": {"every": 2}}, NO_DARK, "no [dark] position"),
    (grid(theta_o_deg={"start": 0, "stop": 10}), SERIAL, "exactly one of 'step' or 'num'"),
    ({**grid(), "repeats": 0}, SERIAL, "repeats: must be in [1, 10000], got 0"),
    ({**grid(), "dwell_s": "long"}, SERIAL, "dwell_s: must be a number, got 'long'"),
    ({"name": "empty"}, SERIAL, "no points"),
])
def test_bad_plans_name_the_problem(raw, cfg, message):
    with pytest.raises(PlanError) as err:
        build_schedule(parse_plan(raw, "p.toml"), cfg)
    assert message in str(err.value)
    assert "\n" not in str(err.value)


def test_arm_may_not_sweep_through_the_source():
    cfg = fast_config()
    cfg["axes"]["arm"]["limits_deg"] = [-170.0, 170.0]
    raw = {"grid": [{"side": "reflection", "theta_i_deg": [30.0],
                     "theta_o_deg": [-60.0, 60.0]}]}
    with pytest.raises(PlanError, match="sweep through the source"):
        build_schedule(parse_plan(raw), parse_config(cfg))
    build_schedule(parse_plan(raw), SERIAL)  # limits [6, 354] keep the arm off the source


def test_beam_and_dark_positions_are_checked_too():
    cfg = fast_config()
    cfg["safety"]["arm_forbidden_deg"] = [[85.0, 95.0]]
    with pytest.raises(PlanError, match=r"\[dark\] position: arm 90 deg inside the forbidden"):
        build_schedule(parse_plan({**grid(), "dark": {"every": 5}}), parse_config(cfg))


def test_skip_forbidden_drops_only_forbidden_points():
    raw = grid(theta_o_deg=[-30.0, -20.0, 10.0], skip_forbidden=True)
    sched = build_schedule(parse_plan(raw), SERIAL)
    assert sched.skipped == 1
    assert sorted(sched.readings["theta_o_deg"]) == [-20.0, 10.0]


def test_gonio_plan_cli_prints_summary_estimates_and_listing(capsys):
    from gonio_cli.main import main

    assert main(["plan", str(EXAMPLES / "plans" / "demo.toml"), "--list"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0] == "plan 'demo' on instrument 'sim-serial'"
    assert "readings: 72 (58 sample, 7 dark, 7 beam)" in out[2]
    estimate = next(line for line in out if "estimated duration" in line)
    assert "(as written: " in estimate
    table = out[out.index(next(x for x in out if x.lstrip().startswith("index"))) + 1:]
    assert len(table) == 72 and table[0].split()[:2] == ["0", "dark"]
