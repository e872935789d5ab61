"""End to end: `gonio scan --sim` on the emulated devices (Modbus TCP stages and detector; ESP +
PM100 over ptys), then reduce and plot; the reduced BSDF matches the generating bench within the
detector's noise (chi-square)."""

import math
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

ROOT = Path(__file__).resolve().parents[2]

PLAN = """
name = "e2e-ground-glass"
instrument = "{instrument}"
averaging = 16

[sample]
id = "e2e-glass"
kind = "hemisphere"
eta = 1.51

[[grid]]
side = ["reflection", "transmission"]
theta_i_deg = [0.0, 30.0]
theta_o_deg = {{ start = -60.0, stop = 60.0, step = 15.0 }}
skip_forbidden = true

[dark]
every = 2

[beam]
every = 6
"""


@pytest.fixture(scope="module", params=[
    pytest.param("sim-modbus.toml", id="modbus"),
    pytest.param("sim-walter-ground-glass.toml", id="serial"),
])
def run_dir(request, tmp_path_factory):
    tmp = tmp_path_factory.mktemp("e2e")
    instrument = ROOT / "examples/instruments" / request.param
    config = instrument.read_text()
    # a drift-free copy (its register maps named by absolute path) with the default
    # multiple-scattering walks: the bench here is checked against itself, built afresh below
    copy = re.sub(r"^ms_walks = \d+", "ms_walks = 65536", config, flags=re.M)
    copy = copy.replace("drift_fraction = 0.01", "drift_fraction = 0.0")
    copy = copy.replace('"../registermaps/', f'"{instrument.parent.parent / "registermaps"}/')
    if copy != config:
        instrument = tmp / "instrument.toml"
        instrument.write_text(copy)
    (tmp / "plan.toml").write_text(PLAN.format(instrument=instrument))
    done = subprocess.run(
        [sys.executable, "-m", "gonio_cli", "scan", str(tmp / "plan.toml"), "--sim", "--out",
         str(tmp / "runs")], capture_output=True, text=True, timeout=240, cwd=ROOT)
    assert done.returncode == 0, done.stderr
    return Path(done.stdout.strip().splitlines()[-1])


def test_reduced_run_matches_the_bench_within_the_noise(run_dir):
    from calibration.pipeline import reduce_run
    from gonio.store import open_run
    from sim.bench import build_bench

    run = open_run(run_dir)
    data = reduce_run(run_dir)
    bench = build_bench(run.config["sim"], run.config["optics"], run.plan["sample"])
    rows = run.readings()
    rows = rows[rows["kind"] == "sample"]
    expected = bench.reduced_bsdf(rows["sample_deg"], rows["arm_deg"])
    ok = data.valid
    assert ok.sum() >= 15
    resid = (data.bsdf - expected) / data.sigma
    # every reading belongs to the positions recorded with it: one taken before the stage
    # arrived, or a late reply answering a later query, would show as a gross outlier
    gross = ok & (np.abs(resid) > 10.0)
    assert not gross.any(), (f"sample readings {rows['index'][gross].tolist()} are "
                             f"{np.round(resid[gross], 1).tolist()} sigma off the bench at "
                             "their recorded positions")
    # The beam normalisation error is common to all points between two beam readings, so a
    # plain chi-square over correlated points is not chi-square distributed; take the common
    # scale out (it must be within the beam's 0.1 %), then the rest must not exceed the noise.
    w = 1.0 / data.sigma[ok] ** 2
    scale = float(np.sum(w * data.bsdf[ok] * expected[ok]) / np.sum(w * expected[ok] ** 2))
    assert scale == pytest.approx(1.0, abs=1e-3)
    chi2 = float(np.sum(((data.bsdf - scale * expected) / data.sigma)[ok] ** 2))
    assert stats.chi2.sf(chi2, int(ok.sum()) - 1) > 1e-3, (chi2, int(ok.sum()))
    assert data.meta["aperture_half_angle_deg"] == pytest.approx(math.degrees(math.atan(0.01)))


def test_reduce_and_plot_commands(run_dir):
    out = subprocess.run([sys.executable, "-m", "gonio_cli", "reduce", str(run_dir)],
                         capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert out.returncode == 0, out.stderr
    csv = Path(out.stdout.strip().splitlines()[-1])
    lines = [ln for ln in csv.read_text().splitlines() if not ln.startswith("#")]
    table = np.genfromtxt(lines, delimiter=",", names=True, dtype=None, encoding=None)
    assert len(table) > 20 and np.all(table["sigma"][table["valid"] == 1] > 0)
    out = subprocess.run([sys.executable, "-m", "gonio_cli", "plot", str(run_dir), "--out",
                          str(run_dir / "p.png")], capture_output=True, text=True, timeout=120,
                         cwd=ROOT)
    assert out.returncode == 0, out.stderr
    assert (run_dir / "p.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_reduce_of_a_missing_run_is_one_clear_error(tmp_path):
    out = subprocess.run([sys.executable, "-m", "gonio_cli", "reduce", str(tmp_path / "nope")],
                         capture_output=True, text=True, timeout=60, cwd=ROOT)
    assert out.returncode != 0 and out.stderr.count("\n") == 1 and "run" in out.stderr
