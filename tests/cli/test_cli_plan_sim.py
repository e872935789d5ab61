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


def test_a_beam_range_the_emulated_beam_reaches_is_said(capsys, tmp_path):
    """calib-angles reads its 1 mW beam on 1e-3 W, the beam's own power, where the meter flags
    the readings over it: `gonio plan --sim` says so in one line; on 1e-2 W it says nothing."""
    shipped = DEMO.parent / "calib-angles.toml"
    text = shipped.read_text().replace('"../instruments/', f'"{DEMO.parents[1]}/instruments/')
    lines = {}
    for range_w in ("1e-2", "1e-3"):
        plan = tmp_path / f"beam-{range_w}.toml"
        plan.write_text(re.sub(r"^range = \S+", f"range = {range_w}", text, flags=re.M))
        assert main(["plan", str(plan), "--sim"]) == 0
        lines[range_w] = [ln for ln in capsys.readouterr().out.splitlines()
                          if ln.startswith("  beam:")]
    assert lines["1e-2"] == []
    assert lines["1e-3"] == [
        "  beam: the emulated beam reaches its [beam] range's full scale (0.001 W): its beam "
        "readings over it are flagged saturated and left out of the normalisation (a larger "
        "[beam] range keeps them all, at a smaller share of its full scale)"]
