"""The real bench first: a lab rehearsal whose scanning process has no [sim] at all.

`gonio emulate lab.toml` serves the lab's devices in one process; the scanning process runs
`gonio scan` on a copy of lab.toml pointed at the printed endpoints, with no [sim] table (what a
lab's own copy holds), so nothing in it can lean on the emulator's truth. The run reduces from
[optics] and the plan's [sample], and fits to the emulated sample's parameters; a second copy
whose [sim] is deliberately wrong reduces the same run identically and scans to the same fit.
"""

import json
import shutil

import numpy as np
import pytest
from gonio_testkit import (
    emulating,
    gonio_cli,
    load_example,
    pointed,
    rewrite_run_files,
    run_dir_of,
    write_toml,
)

from calibration.pipeline import reduce_run
from gonio.store import open_run

SAMPLE = {"id": "rehearsal-gg", "kind": "hemisphere", "eta": 1.51, "lit_from": "air",
          "operator": "test"}
PLAN = {"name": "rehearsal-fit", "averaging": 4, "order": "as-written", "sample": SAMPLE,
        "dark": {"every": 12}, "beam": {"every": 24}, "grid": [
            {"side": "transmission", "theta_i_deg": [0.0, 30.0], "skip_forbidden": True,
             "theta_o_deg": {"start": -60.0, "stop": 60.0, "step": 5.0}},
            {"side": "reflection", "theta_i_deg": [30.0],
             "theta_o_deg": {"start": 12.0, "stop": 60.0, "step": 4.0}}]}
WRONG_SIM = {"time_scale": 3.0, "seed": 99,
             "source": {"power_w": 5.0, "wavelength_nm": 1064.0, "divergence_deg": 2.0},
             "sample": {"kind": "slab", "eta": 2.4, "distribution": "beckmann", "alpha": 0.05},
             "aperture": {"diameter_mm": 1.0, "distance_mm": 900.0},
             "detector": {"dark_current_a": 1e-6, "read_noise_fraction": 0.1}}


@pytest.fixture(scope="module")
def lab(tmp_path_factory):
    """`gonio emulate lab.toml --time-scale inf` in its own process (the lab's own [sim]
    truth: ground glass, GGX alpha 0.394); yields (lab config, {device: (protocol, endpoint)})."""
    cfg = load_example("lab")
    for axis in cfg["axes"].values():
        axis["settle_s"] = 0.0
    path = write_toml(tmp_path_factory.mktemp("lab") / "lab.toml", cfg)
    with emulating(path, "--time-scale", "inf") as endpoints:
        yield cfg, endpoints


def lab_copy(cfg, endpoints, sim=None):
    """The lab's own copy of lab.toml: the printed endpoints, and `sim` as its [sim] (none)."""
    copy = {k: v for k, v in pointed(cfg, endpoints).items() if k != "sim"}
    return copy if sim is None else {**copy, "sim": sim}


def scan(tmp_path, name, instrument):
    plan = write_toml(tmp_path / f"{name}-plan.toml", PLAN)
    proc = gonio_cli("scan", plan, "--instrument", instrument, "--out", tmp_path / name,
                     "--no-plot", timeout=300)
    assert proc.returncode == 0, proc.stderr
    return run_dir_of(proc)


def fit_json(run_dir):
    """`gonio fit RUN --json` with multiple scattering (rough glass): (alpha, sigma, result)."""
    proc = gonio_cli("fit", run_dir, "--json", "--multiple-scattering", "--distribution",
                     "ggx", timeout=300)
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout)
    return out["parameters"]["alpha"]["value"], out["parameters"]["alpha"]["sigma"], out


@pytest.fixture(scope="module")
def runs(lab, tmp_path_factory):
    """Two scans of the rehearsal bench: from a copy with no [sim], and from one whose [sim]
    is deliberately wrong (neither is --sim: both are runs on a real bench)."""
    tmp = tmp_path_factory.mktemp("runs")
    cfg, endpoints = lab
    bare = write_toml(tmp / "lab-copy.toml", lab_copy(cfg, endpoints))
    wrong = write_toml(tmp / "lab-wrong.toml", lab_copy(cfg, endpoints, WRONG_SIM))
    return scan(tmp, "bare", bare), scan(tmp, "wrong", wrong), endpoints


def test_the_record_names_the_bench_the_sample_and_every_device(runs):
    run = open_run(runs[0])
    endpoints = runs[2]
    assert run.meta["sim"] is False and "sim" not in run.config
    assert run.meta["sample"]["id"] == "rehearsal-gg" and run.meta["sample"]["eta"] == 1.51
    assert run.meta["optics"]["aperture_diameter_mm"] == 8.0
    assert run.meta["optics"]["receiver_solid_angle_sr"] == pytest.approx(
        2 * np.pi * (1 - np.cos(np.arctan(4.0 / 400.0))))
    devices = run.meta["sessions"][0]["devices"]
    assert set(devices) == set(endpoints)
    assert devices["esp"]["identity"]["version"].startswith("ESP301")
    assert devices["pm100"]["identity"]["idn"].upper().startswith("THORLABS")
    assert devices["pm100"]["identity"]["sensor_serial"]
    assert devices["azimuth_drive"]["identity"]["serial"]


def test_real_run_reduces_from_optics_and_sample_and_fits_the_emulated_sample(runs):
    data = reduce_run(runs[0])
    assert data.meta["eta"] == 1.51 and data.meta["kind"] == "hemisphere"
    assert data.meta["aperture_half_angle_deg"] == pytest.approx(np.degrees(np.arctan(0.01)))
    assert data.meta.get("model") is None  # no emulator truth in a real run's reduction
    alpha, sigma, out = fit_json(runs[0])
    assert abs(alpha / 0.394 - 1) < 0.02, out  # lab.toml's [sim]: GGX alpha 0.394
    assert sigma < 0.01 * alpha


def test_a_wrong_sim_table_changes_nothing(runs, tmp_path):
    bare, wrong, _ = runs
    # one run reduced under both configs: bit for bit the same
    twin = tmp_path / "twin"
    shutil.copytree(bare, twin)
    config = json.loads((twin / "config.json").read_text())
    rewrite_run_files(twin, config={**config, "sim": WRONG_SIM})
    a, b = reduce_run(bare), reduce_run(twin)
    np.testing.assert_array_equal(a.bsdf, b.bsdf)
    np.testing.assert_array_equal(a.sigma, b.sigma)
    np.testing.assert_array_equal(a.valid, b.valid)
    # and a scan from the copy with the wrong [sim] fits the same sample
    (a_bare, s_bare, _), (a_wrong, s_wrong, _) = fit_json(bare), fit_json(wrong)
    assert abs(a_bare - a_wrong) < 4 * np.hypot(s_bare, s_wrong)
