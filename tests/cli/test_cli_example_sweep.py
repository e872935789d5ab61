"""The shipped example sweep runs as the README shows it (`gonio sweep SWEEP.toml --out F`)
and measures what its comments say: each roughness's transmitted lobe, brightest straight
through at normal incidence, narrowest for the smoothest glass."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from gonio_cli.main import main

SWEEP = Path(__file__).resolve().parents[2] / "examples" / "sweeps" / "roughness.toml"


def test_the_example_sweep_runs_and_measures_the_transmitted_lobes(tmp_path, capsys):
    out = tmp_path / "roughness.npz"
    assert main(["sweep", str(SWEEP), "--out", str(out)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith("swept 6 setting(s) x 10 position(s)") and lines[1] == str(out)
    with np.load(out, allow_pickle=False) as f:
        power = f["power_w"][..., 0, 0]  # (distribution, alpha, sample, arm)
        arm = f["arm_deg"]
        alpha = f["vary_sample.alpha"]
        meta = json.loads(str(f["metadata"]))
    assert power.shape == (2, 3, 2, 5) and list(alpha) == [0.023, 0.394, 0.553]
    assert meta["base_sim"]["sample"]["alpha"] == 0.394  # sim-serial.toml's [sim] is the base
    normal = power[:, :, 0, :]
    assert np.all(normal.argmax(axis=-1) == list(arm).index(180.0))
    falloff = normal[..., list(arm).index(170.0)] / normal[..., -1]  # 10 deg off the peak
    assert np.all(np.diff(falloff, axis=1) > 0)  # rougher glass, wider lobe
