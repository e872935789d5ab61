"""`gonio lut` and `gonio sweep` refuse an output name whose format they cannot write, in one
line and before any work (a table of this size would bake for hours)."""

from __future__ import annotations

import pytest

import model.cluster
import model.lut
from gonio_cli.main import main
from model.lut import TableSpec, bake

HUGE = ["lut", "--kind", "transmission", "--size", "256x256x128", "--samples", "65536"]


@pytest.mark.parametrize("name, instead", [("t.txt", "instead of '.txt'"), ("t", "extensions")])
def test_lut_refuses_a_name_it_cannot_write_before_baking(tmp_path, capsys, monkeypatch, name,
                                                          instead):
    def no_work(*args, **kwargs):
        raise AssertionError("work started before the output name was checked")

    monkeypatch.setattr(model.lut, "bake", no_work)  # what `gonio lut` runs to bake
    monkeypatch.setattr(model.cluster, "dask_client", no_work)  # and to start its workers
    assert main([*HUGE, "--out", str(tmp_path / name)]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.count("\n") == 1
    assert err.startswith(f"gonio lut: error: {tmp_path / name}: a table is written as .npz")
    assert instead in err and not (tmp_path / name).exists()


def test_lut_save_refuses_it_too(tmp_path):
    table = bake(TableSpec(kind="reflection", shape=(2, 2), samples=4, tile_entries=4))
    with pytest.raises(ValueError, match=r"\.npz \(NumPy\) or \.exr"):
        table.save(tmp_path / "t.csv")
    assert table.save(tmp_path / "t.NPZ").is_file()


def test_sweep_refuses_a_name_it_cannot_write_before_sweeping(tmp_path, capsys):
    sweep = tmp_path / "s.toml"
    sweep.write_text("[positions]\nsample_deg = [0.0]\narm_deg = [180.0]\n")
    assert main(["sweep", str(sweep), "--out", str(tmp_path / "s.txt")]) == 2
    out, err = capsys.readouterr()
    assert out == "" and not (tmp_path / "s.txt").exists()
    assert err == f"gonio sweep: error: {tmp_path / 's.txt'}: a sweep is written as .npz " \
                  "(NumPy): give the file that extension\n"
