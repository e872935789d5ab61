"""`gonio sweep`: file checking, the grid-to-array mapping against direct bench evaluations,
and the same numbers (noise included) in-process and on a Dask cluster."""

from __future__ import annotations

import json

import numpy as np
import pytest

from gonio_cli.main import main
from sim.bench import build_power_source
from sim.devices.photodiode import PhotodiodeModel
from sim.sweep import load_sweep, parse_sweep, run_sweep, setting_seed

SWEEP = """
seed = 4
averaging = 2
[sim.source]
power_w = 1e-3
[sim.sample]
kind = "hemisphere"
distribution = "ggx"
eta = 1.51
[vary]
"sample.alpha" = [0.2, 0.394]
"aperture.diameter_mm" = [5.0, 10.0]
[positions]
sample_deg = [0.0, 20.0]
arm_deg = [160.0, 180.0]
"""


@pytest.fixture(scope="module")
def sweep_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("sweep") / "s.toml"
    path.write_text(SWEEP)
    return path


@pytest.fixture(scope="module")
def result(sweep_file):
    return run_sweep(load_sweep(sweep_file))


def test_every_entry_is_its_settings_bench_at_its_position(sweep_file, result):
    sweep = load_sweep(sweep_file)
    assert result.values["power_w"].shape == (2, 2, 2, 2, 1, 1) == sweep.shape
    for (i, j, k, m) in [(0, 0, 0, 0), (1, 0, 1, 1), (0, 1, 1, 0), (1, 1, 0, 1)]:
        cfg = {"source": {"power_w": 1e-3},
               "sample": {"kind": "hemisphere", "distribution": "ggx", "eta": 1.51,
                          "alpha": [0.2, 0.394][i]},
               "aperture": {"diameter_mm": [5.0, 10.0][j]}}
        pos = {"sample": [0.0, 20.0][k], "arm": [160.0, 180.0][m], "elevation": 0.0,
               "azimuth": 0.0}
        power = build_power_source(cfg, lambda p=pos: p, clock=lambda: 0.0).power_w()
        assert result.values["power_w"][i, j, k, m, 0, 0] == power
    # readings: the seeded meter of each setting, in position order
    meter = PhotodiodeModel(None, seed=setting_seed(4, 3))
    first = meter.measure(result.values["power_w"][1, 1, 0, 0, 0, 0], averaging=2)
    assert result.values["reading_w"][1, 1, 0, 0, 0, 0] == first.reading_w
    assert result.values["range_w"][1, 1, 0, 0, 0, 0] == first.range_w
    # straight through the hemisphere at normal incidence is the brightest point
    assert np.all(result.values["power_w"][:, :, 0, 1] > result.values["power_w"][:, :, 0, 0])


def test_same_numbers_on_a_cluster(sweep_file, result):
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False,
                                  dashboard_address=":0") as cluster:
        with distributed.Client(cluster) as client:
            remote = run_sweep(load_sweep(sweep_file), client=client)
    for name, values in result.values.items():
        assert values.tobytes() == remote.values[name].tobytes(), name


def test_cli_writes_axes_quantities_and_metadata(sweep_file, tmp_path, capsys):
    out = tmp_path / "s.npz"
    assert main(["sweep", str(sweep_file), "--out", str(out)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith("swept 4 setting(s) x 4 position(s)") and lines[1] == str(out)
    with np.load(out, allow_pickle=False) as f:
        meta = json.loads(str(f["metadata"]))
        assert list(f["vary_sample.alpha"]) == [0.2, 0.394]
        assert f["saturated"].dtype == bool and f["reading_w"].shape == (2, 2, 2, 2, 1, 1)
    assert meta["axes"][:2] == ["vary_sample.alpha", "vary_aperture.diameter_mm"]
    assert meta["seed"] == 4 and meta["base_sim"]["sample"]["eta"] == 1.51


@pytest.mark.parametrize("doc, message", [
    ({"vary": {"alpha": [1]}, "positions": {"sample_deg": [0], "arm_deg": [180]}},
     "must be <table>.<key>"),
    ({"positions": {"sample_deg": [0]}}, "missing required key 'arm_deg'"),
    ({"positions": {"sample_deg": [0], "arm_deg": ["x"]}}, "list of angles"),
    ({"positions": {"sample_deg": [0], "arm_deg": [180], "tilt_deg": [1]}}, "tilt_deg"),
    ({"vary": {"sample.alpha": [0.3, -1.0]}, "positions": {"sample_deg": [0], "arm_deg": [180]}},
     "setting 1 (sample.alpha=-1.0)"),
    ({"speed": 1}, "unknown key 'speed'"),
])
def test_bad_sweeps_name_the_field(doc, message):
    with pytest.raises(ValueError, match=message.replace("(", r"\(").replace(")", r"\)")):
        parse_sweep(doc)


def test_cli_error_is_one_line(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text('[positions]\nsample_deg = [0]\n')
    assert main(["sweep", str(bad), "--out", str(tmp_path / "x.npz")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("gonio sweep: error:") and "missing required key 'arm_deg'" in err
