"""A PM100 that answers SCPI's not-a-number (9.91E+37, seeded `invalid_prob` fault) during a
`gonio scan --sim`: the engine retries such a reading, records one that stays invalid as
`invalid` with no power, never as light, and reduction leaves it out."""

import tomllib

import numpy as np
from gonio_testkit import EXAMPLES, fast_config, gonio_cli, one_line_error, run_dir_of, write_plan

from calibration.pipeline import reduce_run
from gonio.reading_flags import INVALID, RETRIED, flagged
from gonio.store import open_run

# invalid_prob 0.5 over three tries leaves about one reading in eight invalid: the plan
# allows half its readings to be (gonio.invalid_readings), so that the run goes on
PLAN = {"name": "invalid", "max_invalid_share": 0.5, "dark": {"every": 4}, "beam": {"every": 4},
        "grid": [
    {"side": "reflection", "theta_i_deg": [30.0],
     "theta_o_deg": {"start": -70.0, "stop": 70.0, "step": 10.0}, "skip_forbidden": True}],
    "sample": tomllib.loads((EXAMPLES / "plans" / "demo.toml").read_text())["sample"]}


def test_invalid_readings_are_retried_then_flagged_never_stored_as_power(tmp_path):
    cfg = fast_config(faults={"pm100": {"invalid_prob": 0.5, "seed": 4}})
    path = write_plan(tmp_path, PLAN, cfg)
    proc = gonio_cli("scan", path, "--sim", "--time-scale", "inf", "--out", tmp_path / "runs",
                     "--no-plot", timeout=120)
    assert proc.returncode == 0, proc.stderr
    run = open_run(run_dir_of(proc))
    assert run.meta["status"] == "completed", run.meta["reason"]
    r = run.readings()
    invalid, retried = flagged(r, INVALID), flagged(r, RETRIED)
    assert invalid.any() and (retried & ~invalid).any()  # both cases happen with this seed
    assert (retried | ~invalid).all()  # invalid only after every retry
    assert np.isnan(r["power_w"][invalid]).all() and not r["saturated"][invalid].any()
    assert np.isfinite(r["power_w"][~invalid]).all() and (r["power_w"][~invalid] < 1.0).all()
    assert (r["range_w"][invalid] > 0).all()  # the range it was asked on is kept
    injected = run.meta["sessions"][-1]["faults_injected"]["pm100"]["invalid"]
    assert injected >= 3 * invalid.sum() + (retried & ~invalid).sum()

    data = reduce_run(run.path)  # reduction leaves them out, and its levels stay finite
    samples = r["kind"] == "sample"
    assert len(data.bsdf) == (samples & ~invalid).sum()
    assert np.isfinite(data.meta["beam_mean_w"])
    assert all(np.isfinite(v) for v in data.meta["dark_level_w"].values())


def test_invalid_prob_on_a_device_without_readings_is_one_line(tmp_path):
    cfg = fast_config(faults={"esp": {"invalid_prob": 0.1}})
    proc = gonio_cli("scan", write_plan(tmp_path, PLAN, cfg), "--sim", "--out", tmp_path)
    assert proc.returncode != 0
    assert one_line_error(proc.stderr).endswith(
        "[sim.faults.esp] invalid_prob: only a pm100 detector answers with an invalid reading")
