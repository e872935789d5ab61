"""`gonio plan PLAN --sim`: the duration estimate of the emulated bench, whose moves, settling
and dwell run at its [sim] time_scale while reads take their real time."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from gonio.config import load_config
from gonio.plan import build_schedule, load_plan
from gonio.plan.estimate import READ_OVERHEAD_S, READ_PER_SAMPLE_S
from gonio_cli.main import main

DEMO = Path(__file__).resolve().parents[2] / "examples" / "plans" / "demo.toml"


def estimate_line(capsys, *extra: str) -> str:
    assert main(["plan", str(DEMO), *extra]) == 0
    return next(ln for ln in capsys.readouterr().out.splitlines() if "estimated duration" in ln)


def test_sim_estimates_the_emulated_bench_at_its_time_scale(capsys):
    plan = load_plan(DEMO)
    cfg = load_config(plan.instrument)
    real, emulated = build_schedule(plan, cfg), build_schedule(plan, cfg, time_scale=50.0)
    assert emulated.readings.tobytes() == real.readings.tobytes()  # the same run, another clock
    reads = len(real) * (READ_OVERHEAD_S + READ_PER_SAMPLE_S * plan.averaging)
    assert emulated.estimate_s == pytest.approx((real.estimate_s - reads) / 50.0 + reads)
    assert emulated.estimate_s < real.estimate_s / 10
    line = estimate_line(capsys, "--sim")
    assert line.endswith("on the emulated bench (time_scale 50: moves, settling and dwell 50x "
                         "faster)")
    assert f"({emulated.estimate_s:.1f} s)" in line
    assert not re.search("emulated", estimate_line(capsys))  # a real config's, as before


def test_time_scale_overrides_the_configs_and_needs_sim(capsys):
    assert "time_scale inf: moves, settling and dwell at once" in estimate_line(
        capsys, "--sim", "--time-scale", "inf")
    assert main(["plan", str(DEMO), "--time-scale", "2"]) == 2
    assert "--time-scale applies to emulated devices: use it with --sim" in \
        capsys.readouterr().err
