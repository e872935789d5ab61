"""A calibration run's plot shows what it measures (calibration.calplot), chosen by the
`calibrates` its plan declares and its record carries, never a BSDF of its readings."""

from __future__ import annotations

import struct
from pathlib import Path

import pytest

from calibration.calplot import PLOTS
from gonio.errors import PlanError
from gonio.plan import CALIBRATES, load_plan, parse_plan
from gonio.record import run_record
from gonio.store import open_run
from gonio_cli.main import main

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"

APERTURE_SCAN = f"""
name = "aperture-scan"
calibrates = "aperture"
instrument = "{EXAMPLES / 'instruments' / 'sim-serial.toml'}"
order = "as-written"
[sample]
id = "reference"
kind = "hemisphere"
eta = 1.51
[[grid]]
side = "reflection"
theta_i_deg = 90.0
theta_o_deg = {{ start = 89.9, stop = 89.0, step = 0.1 }}
[[grid]]
side = "transmission"
theta_i_deg = 90.0
theta_o_deg = {{ start = 89.0, stop = 90.0, step = 0.1 }}
[dark]
every = 7
[beam]
every = 30
"""


def png_size(path: Path) -> tuple[int, int]:
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    return struct.unpack(">II", data[16:24])


def test_an_aperture_run_is_plotted_as_its_beam_scan(tmp_path, capsys):
    plan = tmp_path / "aperture-scan.toml"
    plan.write_text(APERTURE_SCAN)
    assert main(["scan", str(plan), "--sim", "--time-scale", "inf", "--no-progress",
                 "--out", str(tmp_path / "runs")]) == 0
    run = Path(capsys.readouterr().out.splitlines()[-1])
    assert run_record(open_run(run))["calibrates"] == "aperture"
    # one panel (the arm scan), 4.2 + 0.8 in wide at 110 dpi; a BSDF plot has one per side
    assert png_size(run / "plot.png") == (550, 418)
    assert main(["plot", str(run), "--fit"]) == 2
    assert "calibrates the aperture: no BSDF to fit" in capsys.readouterr().err


def test_the_example_calibration_plans_say_what_they_calibrate():
    assert set(PLOTS) == set(CALIBRATES)
    for kind in CALIBRATES:
        assert load_plan(EXAMPLES / "plans" / f"calib-{kind}.toml").calibrates == kind
    assert load_plan(EXAMPLES / "plans" / "demo.toml").calibrates is None


def test_an_unknown_kind_is_refused():
    with pytest.raises(PlanError, match="plan: calibrates: must be one of detector, aperture, "
                                        "angles; got 'beam'"):
        parse_plan({"calibrates": "beam", "grid": {"theta_i_deg": 0, "theta_o_deg": 10}})
