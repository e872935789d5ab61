"""`gonio reduce RUN --integrals` on a small emulated run prints the integrals' table before the
CSV's path and writes the JSON file; a cheap coverage check of U = 2u over bench seeds (slow)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest
from fitting_bench_runs import instrument, plan, scan

from gonio_cli.main import main

ROOT = Path(__file__).resolve().parents[2]
QUANTITIES = ("reflectance", "tis_backward", "gloss", "transmittance", "tis_forward", "haze")


@pytest.fixture(scope="module")
def small_run(tmp_path_factory) -> Path:
    """A small emulated run at 60 deg, both sides (GGX alpha 0.394, single scattering)."""
    tmp = tmp_path_factory.mktemp("integrals")
    cfg = instrument(tmp, {"sample": {"distribution": "ggx", "alpha": 0.394,
                                      "multiple_scattering": False}})
    grids = [{"side": side, "theta_i_deg": [60.0], "skip_forbidden": True,
              "theta_o_deg": {"start": -85.0, "stop": 85.0, "step": 10.0}}
             for side in ("reflection", "transmission")]
    return scan(plan(tmp, "integrals", grids, dark_every=10, beam_every=10), cfg, tmp / "runs")


def test_an_unwritable_integrals_json_is_refused_before_anything_is_written(small_run, tmp_path,
                                                                            capsys):
    reduced = small_run / "reduced.csv"
    before = reduced.read_bytes() if reduced.exists() else None
    missing = tmp_path / "no-such-folder" / "x.json"
    for path, said in ((missing, f"cannot write in {missing.parent}"), (tmp_path, "is a folder")):
        assert main(["reduce", str(small_run), "--integrals-json", str(path)]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and f"--integrals-json {path}: {said}" in err
    assert (reduced.read_bytes() if reduced.exists() else None) == before  # nothing written


def test_reduce_prints_the_integrals_and_writes_their_json(small_run, tmp_path, capsys):
    run = small_run
    out_json = tmp_path / "integrals.json"
    assert main(["reduce", str(run), "--integrals-json", str(out_json)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[-1] == str(run / "reduced.csv")
    head = next(i for i, line in enumerate(lines) if line.split()[:3] == ["theta_i", "quantity",
                                                                          "value"])
    rows = {line.split()[1]: line.split() for line in lines[head + 1:head + 7]}
    assert set(rows) == set(QUANTITIES)
    written = json.loads(out_json.read_text())
    by_name = {i["quantity"]: i for i in written["integrals"]}
    assert set(by_name) == set(QUANTITIES)
    for name, row in rows.items():
        assert float(row[2]) == pytest.approx(by_name[name]["value"], rel=1e-4)
        assert by_name[name]["U"] == pytest.approx(2 * by_name[name]["u"])
        assert by_name[name]["u"] > 0
    assert 0.0 < by_name["reflectance"]["value"] < 0.2
    assert 0.8 < by_name["transmittance"]["value"] < 1.0
    assert 0.0 < by_name["haze"]["value"] < 1.0
    assert written["fill_model"]["distribution"] and written["assumptions"]


@pytest.mark.slow
def test_u_covers_the_truth_over_a_few_bench_seeds(tmp_path):
    sys.path.insert(0, str(ROOT / "bench"))
    try:
        import integral_coverage
    finally:
        sys.path.remove(str(ROOT / "bench"))
    pairs = [pair for seed in (1, 2, 3) for pair in integral_coverage.one_run(seed, tmp_path)]
    inside = sum(abs(found.value - truth) <= 2 * found.u for found, truth in pairs)
    assert len(pairs) == 33
    assert inside >= 0.85 * len(pairs), [(f.theta_i_deg, f.name, f.value, t, f.u)
                                         for f, t in pairs]
