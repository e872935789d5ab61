"""`gonio lut` end to end: files, metadata, bits equal across in-process and a Dask cluster
reached by address over real loopback TCP, and one-line errors."""

from __future__ import annotations

import json

import numpy as np
import pytest

from gonio_cli.main import main
from model.cluster import dask_client
from model.lut import TableSpec, bake, load_table

ARGS = ["lut", "--kind", "transmission", "--size", "4x3x4", "--samples", "64",
        "--tile-entries", "7", "--dtype", "float32"]


@pytest.fixture(scope="module")
def scheduler_address():
    """One 2-worker cluster in this process, listening on 127.0.0.1 TCP."""
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False,
                                  protocol="tcp://", host="127.0.0.1",
                                  dashboard_address=":0") as cluster:
        yield cluster.scheduler_address


def test_lut_writes_the_table_its_axes_and_metadata(tmp_path, capsys):
    out = tmp_path / "t.npz"
    assert main([*ARGS, "--out", str(out)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[-1] == str(out) and "baked transmission 4x3x4 float32" in lines[0]
    table = load_table(out)
    spec = TableSpec(kind="transmission", shape=(4, 3, 4), samples=64, tile_entries=7,
                     dtype="float32")
    assert table.spec == spec
    assert table.data.tobytes() == bake(spec).data.tobytes()
    with np.load(out, allow_pickle=False) as f:
        meta = json.loads(str(f["metadata"]))
        assert np.allclose(f["axis_eta"] * f["axis_eta"][::-1], 1.0)
    assert "RoughDielectric" in meta["model"] and "correlated" in meta["model"]
    assert meta["definitions"]["transmittance"].startswith("eta^2 times the integral over")
    assert meta["validation"] is None


def test_cluster_by_address_gives_the_same_bits_and_validates(tmp_path, scheduler_address,
                                                               capsys):
    local, remote = tmp_path / "local.npz", tmp_path / "remote.npz"
    assert main([*ARGS, "--out", str(local)]) == 0
    assert main([*ARGS, "--out", str(remote), "--scheduler", scheduler_address, "--validate",
                 "--validate-points", "50", "--reference-samples", "512"]) == 0
    assert f"Dask cluster at {scheduler_address}" in capsys.readouterr().out
    a, b = load_table(local), load_table(remote)
    assert a.data.tobytes() == b.data.tobytes()
    report = b.validation
    assert report["entries_checked"] == 48 and report["points_checked"] == 50
    # 64 Sobol points per entry on values up to 1/eta^2 = 6.25: percent-level errors
    assert 0 < report["entry_rms"] <= report["entry_max"] < 0.2


@pytest.mark.parametrize("extra, message", [
    (["--size", "8x8"], "a transmission table has 3 axes"),
    (["--samples", "100"], "power of two"),
    (["--workers", "0"], "--workers must be >= 1"),
    (["--kind", "reflection", "--size", "4x4", "--multiple-scattering"], "single scattering"),
    (["--validate", "--validate-points", "0"], "--validate-points must be >= 1"),
    (["--eta", "1"], "other than 1"),
    (["--eta", "3"], "give a value in"),
    (["--kind", "reflection", "--size", "4x3", "--remap", "tir"], "is for transmission"),
])
def test_bad_arguments_are_one_line_errors(tmp_path, capsys, extra, message):
    assert main([*ARGS, *extra, "--out", str(tmp_path / "x.npz")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("gonio lut: error:") and message in err and "\n" not in err
    assert not (tmp_path / "x.npz").exists()


def test_unwritable_output_is_one_line(tmp_path, capsys):
    assert main([*ARGS, "--out", str(tmp_path / "missing" / "x.npz")]) == 2
    out, err = capsys.readouterr()
    assert "cannot write" in err and "checked before baking" in err
    assert "baked" not in out  # refused before the bake, not after it


def test_unreachable_scheduler_is_named():
    with pytest.raises(ValueError, match="cannot reach the Dask scheduler at 'tcp://127.0.0.1:9'"):
        with dask_client(scheduler="tcp://127.0.0.1:9", connect_timeout_s=0.5):
            pass


def test_remap_none_keeps_the_old_axes_and_eta_fixes_the_index(tmp_path, capsys):
    old, fixed = tmp_path / "old.npz", tmp_path / "fixed.exr"
    assert main([*ARGS, "--remap", "none", "--out", str(old)]) == 0
    table = load_table(old)
    assert table.spec.remap == "none"
    with np.load(old, allow_pickle=False) as f:  # texel-centre nodes, N.V itself
        assert np.allclose(f["axis_cos_theta"], (np.arange(4) + 0.5) / 4)
    assert json.loads(str(np.load(old)["metadata"]))["definitions"]["transmittance"].startswith(
        "integral over the transmitted")
    assert main(["lut", "--kind", "transmission", "--eta", "1.5", "--size", "6x4", "--samples",
                 "64", "--dtype", "float16", "--out", str(fixed), "--validate",
                 "--validate-points", "40", "--reference-samples", "512"]) == 0
    assert "baked transmission at eta 1.5 and 0.666667 6x4 float16" in capsys.readouterr().out
    table = load_table(fixed)
    assert table.spec.shape == (6, 4) and table.spec.channels == ("transmittance",
                                                                  "transmittance_reciprocal")
    assert table.data.shape == (4, 6, 2) and table.validation["points_checked"] == 40
    assert table.validation["edge_points"] is not None  # the 1/1.5 channel has a TIR edge
    # a smooth surface at normal view: (1 - F) / eta^2 on each side
    t = table.lookup(1.0, 0.0)
    assert np.allclose(t, [0.96 / 1.5**2, 0.96 * 1.5**2], rtol=2e-3)

