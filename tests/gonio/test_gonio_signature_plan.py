"""Signature readings in plans: [signature] every = N (right after every N-th sample reading, at
its arm, elevation and azimuth, the sample at the instrument's [signature] position), one pass
after the sample readings (theirs or its own arm_deg), ranges, a deterministic schedule that a
resume rebuilds exactly, and one clear error for each bad field."""

import json

import numpy as np
import pytest
from gonio_testkit import fast_config

from gonio.config import parse_config
from gonio.errors import ConfigError, PlanError
from gonio.plan import build_schedule, parse_plan, summary


def config(**changes):
    cfg = fast_config("sim-serial", elevation=True)
    cfg.update(changes)
    return parse_config(cfg)


CFG = config()
NO_SIGNATURE = parse_config({k: v for k, v in fast_config(elevation=True).items()
                             if k != "signature"})


def plan(signature, **extra):
    return parse_plan({
        "grid": [{"side": "transmission", "theta_i_deg": [0.0, 20.0],
                  "theta_o_deg": [-8.0, -4.0, 4.0, 8.0], "phi_o_deg": [0.0, 5.0],
                  "range": [1e-6, 1e-5]}],
        "dark": {"every": 5}, "beam": {"every": 7}, "repeats": 2, "signature": signature,
        **extra}, "p.toml")


def test_every_n_follows_the_sample_reading_just_taken():
    sched = build_schedule(plan({"every": 3}), CFG).readings
    assert list(sched["index"]) == list(range(len(sched)))
    is_sample = sched["kind"] == "sample"
    sig = np.flatnonzero(sched["kind"] == "signature")
    n_sample = int(is_sample.sum())
    assert len(sig) == n_sample // 3
    for k in sig:
        before = sched[k - 1]
        assert before["kind"] == "sample"  # right after it, before any dark or beam reading
        assert np.cumsum(is_sample)[k] % 3 == 0
        row = sched[k]
        assert row["sample_deg"] == 90.0  # retracted: the instrument's [signature] position
        for role in ("arm", "elevation", "azimuth"):
            assert row[f"{role}_deg"] == before[f"{role}_deg"]
        assert row["range_w"] == before["range_w"]  # the sample reading's own range
        assert row["point"] == before["point"] and row["repeat"] == before["repeat"]
        assert np.isnan(row["theta_i_deg"]) and row["side"] == ""
    text = summary(plan({"every": 3}), CFG, build_schedule(plan({"every": 3}), CFG))
    assert f"{len(sig)} signature" in text and "after every 3 sample reading(s)" in text


def test_the_schedule_is_deterministic_and_a_resume_rebuilds_it():
    raw = {"grid": [{"theta_i_deg": [30.0], "theta_o_deg": [10.0, 20.0, 40.0]}],
           "signature": {"every": 2, "range": 1e-6}, "dark": {"every": 2}}
    first = build_schedule(parse_plan(raw), CFG).readings
    again = build_schedule(parse_plan(json.loads(json.dumps(raw))), CFG).readings  # plan.json
    for name in first.dtype.names:
        np.testing.assert_array_equal(first[name], again[name])
    assert set(first["range_w"][first["kind"] == "signature"]) == {1e-6}


def test_one_pass_after_the_sample_readings_at_their_positions():
    sched = build_schedule(plan({}), CFG).readings
    kinds = sched["kind"]
    last = int(np.flatnonzero(kinds == "sample")[-1])
    block = sched[last + 1:]
    sig = block[block["kind"] == "signature"]
    assert list(block["kind"][len(sig):]) == ["dark", "dark", "beam"]  # closed by dark, beam
    assert list(block["kind"][:len(sig)]) == ["signature"] * len(sig)
    samples = sched[kinds == "sample"]
    where = {(r["arm_deg"], r["elevation_deg"], r["azimuth_deg"], r["range_w"])
             for r in samples}
    assert len(sig) == len(where)  # each distinct position and range once
    assert {(r["arm_deg"], r["elevation_deg"], r["azimuth_deg"], r["range_w"])
            for r in sig} == where


def test_a_prompted_pass_on_a_grid_of_its_own():
    p = plan({"pass": "prompted", "arm_deg": {"start": 170.0, "stop": 190.0, "step": 5.0}})
    sched = build_schedule(p, CFG)
    sig = sched.readings[sched.readings["kind"] == "signature"]
    assert list(sig["arm_deg"]) == [170.0, 175.0, 180.0, 185.0, 190.0]
    assert set(sig["sample_deg"]) == {90.0} and set(sig["elevation_deg"]) == {0.0}
    assert set(sig["point"]) == {-1}
    assert set(sig["range_w"]) == {0.0}  # the plan's range (the instrument's: auto)
    assert "waits for the operator" in summary(p, CFG, sched)


@pytest.mark.parametrize("signature, message", [
    ({"every": 0}, "p.toml: [signature] every: must be in [1, 1e+06], got 0"),
    ({"every": 2, "pass": "after"}, "p.toml: [signature] every: interleaves"),
    ({"pass": "interleaved"}, 'p.toml: [signature] pass: "interleaved" needs every = N'),
    ({"pass": "sometimes"}, "p.toml: [signature] pass: must be one of interleaved, after, "
                            "prompted; got 'sometimes'"),
    ({"every": 2, "arm_deg": [170.0]}, "p.toml: [signature] arm_deg: a grid of its own"),
    ({"arm_deg": []}, "p.toml: [signature] arm_deg: must not be empty"),
    ({"range": "high"}, 'p.toml: [signature] range: must be "auto" or a fixed full scale'),
    ({"evry": 2}, "p.toml: [signature]: unknown key 'evry'"),
    ({"arm_deg": [3.0]}, "[signature] arm_deg 3: outside the arm travel [6, 354]"),
    ({"arm_deg": [140.0, 272.0]}, "[signature] arm_deg 272: arm 272 deg inside the forbidden"),
])
def test_bad_signature_fields_are_one_clear_error(signature, message):
    cfg = fast_config("sim-serial", elevation=True)
    cfg["safety"]["arm_forbidden_deg"] = [[268.0, 276.0]]
    with pytest.raises(PlanError) as err:
        build_schedule(plan(signature), parse_config(cfg))
    assert message in str(err.value) and "\n" not in str(err.value)


def test_an_instrument_without_a_signature_position_is_refused_naming_both():
    with pytest.raises(PlanError) as err:
        build_schedule(plan({"every": 2}), NO_SIGNATURE)
    assert str(err.value).startswith("p.toml: [signature]: asks for signature readings but the "
                                     "instrument 'sim-serial'")
    assert "has no [signature] position" in str(err.value)


@pytest.mark.parametrize("table, message", [
    ({"sample_deg": 90.0, "arm_deg": 180.0}, "config: [signature]: unknown key 'arm_deg'"),
    ({}, "config: [signature]: missing required key 'sample_deg'"),
    ({"sample_deg": "out"}, "config: [signature] sample_deg: must be a number"),
])
def test_bad_instrument_signature_positions(table, message):
    with pytest.raises(ConfigError) as err:
        config(signature=table)
    assert message in str(err.value)


def test_a_signature_position_outside_the_sample_travel_is_refused():
    cfg = fast_config("sim-serial", elevation=True)
    cfg["signature"] = {"sample_deg": 200.0}
    cfg["axes"]["sample"]["limits_deg"] = [-120.0, 120.0]
    with pytest.raises(PlanError, match=r"\[signature\] sample_deg 200 is outside the sample "
                                        r"travel \[-120, 120\]"):
        build_schedule(plan({"every": 1}), parse_config(cfg))
