"""A lab user's round trips through the real CLI on the README's demo run: `gonio reduce` writes
the export's reduced CSV, imports carry the run's record and the index on, text exports write
angles without float noise and values with every digit, and the budget is in `fit --json`.
Cost: one demo scan (about 10 s) and a few reductions and single-scattering fits (about 30 s)."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest
from gonio_testkit import ROOT, gonio_cli, run_dir_of

from calibration.exports.astm import read_astm
from calibration.exports.measured import ANGLE_DECIMALS
from calibration.pipeline import reduce_run
from gonio.record import run_record
from gonio.store import open_run
from gonio_cli.main import main


@pytest.fixture(scope="module")
def demo(tmp_path_factory) -> Path:
    """The README's first command, on the emulated bench."""
    out = tmp_path_factory.mktemp("demo")
    proc = gonio_cli("scan", ROOT / "examples/plans/demo.toml", "--sim", "--out", out,
                     "--no-plot")
    assert proc.returncode == 0, proc.stderr
    return run_dir_of(proc)


def comments(path: Path) -> list[str]:
    """The `# ...` header lines of a gonio text file, without the `# `."""
    return [ln[2:] for ln in path.read_text().splitlines() if ln.startswith("# ")]


def record_of(path: Path) -> dict:
    """The run's record a gonio text file carries: its `key: JSON` lines before `quantity`."""
    lines = comments(path)
    end = next(n for n, ln in enumerate(lines) if ln.startswith("quantity: "))
    return {k: json.loads(v) for k, v in (ln.split(": ", 1) for ln in lines[:end])}


def rows(path: Path) -> list[dict]:
    return list(csv.DictReader(ln for ln in path.read_text().splitlines()
                               if not ln.startswith("#")))


def fit_json(capsys, *argv: str) -> dict:
    assert main(["fit", *argv, "--json", "--distribution", "ggx"]) == 0
    return json.loads(capsys.readouterr().out.strip().splitlines()[-1])


def test_reduce_writes_the_exports_csv_and_fit_imports_it_with_its_budget(demo, tmp_path,
                                                                           capsys):
    assert main(["reduce", str(demo)]) == 0
    assert capsys.readouterr().out.splitlines()[-1] == str(demo / "reduced.csv")
    assert main(["export", str(demo), "--format", "csv", "--out", str(tmp_path / "r.csv")]) == 0
    assert (demo / "reduced.csv").read_text() == (tmp_path / "r.csv").read_text()
    assert record_of(demo / "reduced.csv") == json.loads(json.dumps(run_record(open_run(demo))))
    table = rows(demo / "reduced.csv")
    imported = fit_json(capsys, "--import", str(demo / "reduced.csv"))  # no --eta
    assert imported["parameters"]["eta"]["value"] == 1.51
    fitted = fit_json(capsys, str(demo))
    # the budget, against its components' columns in the CSV
    f = np.array([float(r["bsdf"]) for r in table])
    u = np.array([float(r["sigma"]) for r in table])
    good = (np.array([float(r["valid"]) for r in table]) == 1) & (u > 0) & (f != 0)
    names = sorted(n[2:] for n in table[0] if n.startswith("u_"))
    for out in (fitted, imported):
        budget = out["budget"]
        assert sorted(budget["components"]) == names and budget["points"] == int(good.sum())
        for name, c in budget["components"].items():
            u_c = np.array([float(r[f"u_{name}"]) for r in table])[good]
            assert c["median_relative"] == pytest.approx(np.median(u_c / np.abs(f[good])),
                                                         rel=1e-9)
            assert c["max_share"] == pytest.approx(np.max(u_c / u[good]), rel=1e-9)
        assert budget["coverage_k"] == 2.0
    # the CSV's facts carry which components are shared and the budget's notes
    assert {c["kind"] for c in fitted["budget"]["components"].values()} == {"own", "shared"}
    assert imported["budget"] == fitted["budget"] and fitted["budget"]["notes"]


def test_text_exports_round_angles_and_keep_every_digit_of_the_values(demo, tmp_path, capsys):
    data = reduce_run(demo)
    for what in ("reduced", "raw"):
        out = tmp_path / f"{what}.csv"
        assert main(["export", str(demo), "--format", "csv", "--what", what, "--out",
                     str(out)]) == 0
        for row in rows(out):
            for name, text in row.items():
                if name.endswith("_deg") and text:
                    assert text == repr(round(float(text), ANGLE_DECIMALS)), (name, text)
    reduced = rows(tmp_path / "reduced.csv")
    assert {r["theta_o_deg"] for r in reduced} >= {"10.0", "30.0", "150.0"}
    np.testing.assert_array_equal([float(r["bsdf"]) for r in reduced], data.bsdf)
    np.testing.assert_allclose([float(r["theta_o_deg"]) for r in reduced],
                               np.degrees(np.arccos(data.wo[:, 2])), rtol=0, atol=5e-10)
    assert main(["export", str(demo), "--format", "astm", "--out", str(tmp_path / "r.astm")]) == 0
    lines = (tmp_path / "r.astm").read_text().splitlines()
    body = lines[next(n for n, ln in enumerate(lines) if ln.startswith("VARS ")) + 1:]
    for line in body:
        for text in line.split(",")[:4]:
            # the radians of a whole number of 1e-9 degrees (astm.radians_text)
            assert text == repr(math.radians(round(math.degrees(float(text)), 9)) + 0.0), text
    good = data.subset(data.valid & data.transmission)
    np.testing.assert_array_equal(read_astm(tmp_path / "r.astm").values[:, 0], good.bsdf)
    assert main(["export", str(demo), "--format", "zemax", "--force", "--distribution", "ggx",
                 "--out", str(tmp_path / "z.bsdf")]) == 0
    capsys.readouterr()
    lines = (tmp_path / "z.bsdf").read_text().splitlines()
    for key in ("AngleOfIncidence", "ScatterAzimuth", "ScatterRadial"):
        grid = lines[next(n for n, ln in enumerate(lines) if ln.startswith(key)) + 1].split()
        assert all(t == repr(round(float(t), ANGLE_DECIMALS)) for t in grid), (key, grid)
    incidence = lines[next(n for n, ln in enumerate(lines) if ln.startswith("AngleOf")) + 1]
    assert float(incidence.split()[1]) == pytest.approx(
        math.degrees(math.asin(math.sin(math.radians(30.0)) / 1.51)), abs=5e-10)


def test_imports_carry_the_record_and_read_the_index_of_gonios_files(demo, tmp_path, capsys):
    record = json.loads(json.dumps(run_record(open_run(demo))))
    made = {"csv": ("r.csv",), "astm": ("r.astm",), "netcdf": ("r.nc",),
            "zemax": ("z.bsdf", "--force", "--distribution", "ggx")}
    for fmt, (name, *options) in made.items():
        assert main(["export", str(demo), "--format", fmt, "--out", str(tmp_path / name),
                     *options]) == 0
    capsys.readouterr()
    for name in ("r.csv", "r.astm", "r-BRDF.astm", "r.nc", "z.bsdf", "z-BRDF.bsdf"):
        out = tmp_path / f"from-{name}.csv"
        assume = [] if name.endswith((".csv", ".nc")) else ["--sigma-relative", "0.02"]
        assert main(["reduce", "--import", str(tmp_path / name), "--out", str(out),
                     *assume]) == 0, name  # no --eta
        printed = capsys.readouterr().out.splitlines()
        assert printed[0].startswith(f"imported {tmp_path / name}: eta 1.51,"), printed[0]
        assert {ln.split()[0] for ln in printed[3:-1]} == {"0", "30"}, name  # the incidences
        expected = ({k: v for k, v in record.items() if v is not None} if name.endswith(".nc")
                    else record)  # NetCDF attributes hold no null
        assert record_of(out) == expected, name


def test_missing_import_inputs_are_one_error(tmp_path, capsys):
    plain = tmp_path / "plain.csv"
    plain.write_text("theta_i,phi_i,theta_o,phi_o,bsdf\n0,0,10,0,0.1\n0,0,20,0,0.05\n")
    assert main(["reduce", "--import", str(plain)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and f"{plain}: 3 inputs missing: (1) " in err
    assert "--sigma-relative FRACTION" in err and "give --eta" in err and "give --out CSV" in err
    assert main(["fit", "--import", str(plain), "--eta", "1.5", "--sigma-relative", "20"]) == 2
    assert "--sigma-relative must be in (0, 10), got 20.0" in capsys.readouterr().err
