"""The shipped plans of samples beside the microfacet interface (a matte paint, a white
reference, a polished mirror, an ABg scatterer) scan on their emulated instruments, reduce and
plot, as a user runs them: the real CLI, emulators on ptys, each plan on a coarse test grid."""

import json
import tomllib

import pytest
from gonio_testkit import EXAMPLES, gonio_cli, load_example, run_dir_of, write_toml

PLANS = EXAMPLES / "plans"
QUIET = ("--sim", "--time-scale", "inf", "--no-progress")
#: A coarse grid per plan: the shipped plan's incidences, a few viewing angles (the mirror's
#: across its specular peak and its halo).
TEST_GRIDS = {
    "matte-paint": [{"side": "reflection", "theta_i_deg": [0.0, 30.0],
                     "theta_o_deg": [-60.0, -20.0, 15.0, 30.0, 45.0]}],
    "white-reference": [{"side": "reflection", "theta_i_deg": [0.0, 45.0],
                         "theta_o_deg": [-45.0, -10.0, 20.0, 60.0]}],
    "polished-mirror": [{"side": "reflection", "theta_i_deg": 10.0,
                         "theta_o_deg": [-40.0, 9.0, 10.0, 11.0, 30.0]}],
    "abg-scatterer": [{"side": "reflection", "theta_i_deg": 30.0,
                       "theta_o_deg": [-30.0, 20.0, 29.0, 30.0, 60.0]}],
}
@pytest.mark.parametrize("name", sorted(TEST_GRIDS))
def test_a_family_plan_scans_reduces_and_plots_on_its_emulated_instrument(name, tmp_path):
    plan = tomllib.loads((PLANS / f"{name}.toml").read_text())
    instrument = (PLANS / plan.pop("instrument")).resolve()
    assert instrument.exists(), instrument
    assert instrument.stem == f"sim-{name}"
    cfg = load_example(instrument.stem)
    grids = [{**grid, "skip_forbidden": True} for grid in TEST_GRIDS[name]]
    plan.update(grid=grids, dark={"every": 6}, beam={"every": 6})
    plan_path = write_toml(tmp_path / f"{name}.toml", plan)
    scan = gonio_cli("scan", plan_path, "--instrument", write_toml(tmp_path / "cfg.toml", cfg),
                     *QUIET, "--no-plot", "--out", tmp_path / "runs", timeout=600)
    assert scan.returncode == 0, scan.stderr
    run = run_dir_of(scan)
    assert json.loads((run / "meta.json").read_text())["status"] == "completed"
    # a sample without an index gets its angle terms from the fit over families (issue 37):
    # until then its slope fit has no eta, and U is stated without them
    no_index = ["--no-angle-terms"] if plan["sample"].get("eta") is None else []
    reduced = gonio_cli("reduce", run, *no_index, timeout=600)
    assert reduced.returncode == 0, reduced.stderr
    plotted = gonio_cli("plot", run, *no_index, timeout=600)
    assert plotted.returncode == 0, plotted.stderr
    assert (run / "plot.png").stat().st_size > 0
    rows = (run / "reduced.csv").read_text().splitlines()
    assert len(rows) > len(TEST_GRIDS[name][0]["theta_o_deg"])
