"""Signature readings on the emulated bench (`gonio scan --sim`, ESP + PM100 over ptys): near the
straight-through beam a halo of the source optics is a large share of a semi-smooth sample's
transmitted wings. Reduced without subtraction the BSDF there is off the bench's noiseless
expectation by many sigma (and flagged); with the signature subtracted it agrees within sigma."""

import sys
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "gonio"))
from gonio_testkit import fast_config, gonio_cli, run_dir_of, write_plan  # noqa: E402

#: A halo holding 0.1 % of the beam, 1 degree wide with a gamma^-3 tail, and a little stray light
#: from the arm; the sample's transmitted lobe (Beckmann 0.1) falls much faster off the axis.
STRAY = {"halo_fraction": 1e-3, "halo_width_deg": 1.0, "halo_slope": 3.0,
         "arm_fraction": 2e-7, "arm_variation": 0.5}
THETA_O = [*np.arange(-12.0, -1.5, 1.0), *np.arange(2.0, 12.5, 1.0)]  # off the direct beam


def plan(signature: dict) -> dict:
    return {"name": "signature", "averaging": 16,
            "sample": {"id": "semi-smooth", "kind": "hemisphere", "eta": 1.51},
            "grid": [{"side": "transmission", "theta_i_deg": [0.0],
                      "theta_o_deg": [float(t) for t in THETA_O]}],
            "dark": {"every": 2}, "beam": {"every": 12}, "signature": signature}


def scan(tmp_path: Path, signature: dict, stdin: str | None = None):
    cfg = fast_config("sim-serial")
    cfg["sim"]["sample"] = {"distribution": "beckmann", "alpha": 0.1}
    cfg["sim"]["stray"] = STRAY
    # the emulated meter and aperture are exact: the pulls below weigh the halo against noise
    cfg["detector"].update(linearity_rel=0.0, range_gain_rel=0.0)
    cfg["optics"]["aperture_diameter_tolerance_mm"] = 0.0
    path = write_plan(tmp_path, plan(signature), cfg)
    done = gonio_cli("scan", path, "--sim", "--time-scale", "inf", "--out", tmp_path / "runs",
                     input=stdin, timeout=240)
    return done


@pytest.fixture(scope="module")
def interleaved(tmp_path_factory):
    done = scan(tmp_path_factory.mktemp("sig"), {"every": 1})
    assert done.returncode == 0, done.stderr
    return run_dir_of(done)


def truth(run_dir: Path) -> np.ndarray:
    """The bench's noiseless reduced value of the sample alone (no instrument scatter), as the
    beam readings normalise it: they hold the halo's core inside the aperture on the beam axis
    too (a share s of the direct beam, here 1.6e-4), which no reading can tell from the beam,
    so every value comes out 1 / (1 + s) of the sample's."""
    from gonio.store import open_run
    from sim.bench import build_bench

    run = open_run(run_dir)
    bench = build_bench(run.config["sim"], run.config["optics"], run.plan["sample"])
    rows = run.readings()
    rows = rows[rows["kind"] == "sample"]
    core = (bench.stray.fraction(180.0, 0.0, bench.integral.aperture_rad)
            / bench.direct_beam_fraction(180.0))
    assert 1e-4 < core < 3e-4
    return bench.reduced_bsdf(rows["sample_deg"], rows["arm_deg"]) / (1.0 + core)


def pulls(data, expected):
    return (data.bsdf - expected) / data.sigma


def test_without_subtraction_biased_and_flagged_with_it_within_sigma(interleaved):
    from calibration.pipeline import reduce_run
    from gonio.store import open_run

    plain = reduce_run(interleaved)
    expected = truth(interleaved)
    raw = pulls(plain, expected)
    meta = plain.meta["signature"]
    assert meta["readings"] == len(THETA_O) and not meta["subtracted"]
    flagged = plain.flags == "signature"
    assert flagged.sum() == meta["flagged"] >= 6
    assert not plain.valid[flagged].any()  # left out unless subtracted
    # the halo biases them (upwards; the arm's stray light, below the dark position's far from
    # the beam, downwards) by many sigma
    assert np.all(np.abs(raw[flagged]) > 5.0) and np.median(raw[flagged]) > 100.0, raw

    sub = reduce_run(interleaved, subtract_signature=True)
    assert sub.meta["signature"]["subtracted"]
    assert np.array_equal(sub.flags, plain.flags)
    # flagged points with a signal above the dark limit are kept once the signature is out
    assert sub.valid[flagged & (expected > 1e-4)].all() and (flagged & sub.valid).sum() >= 4
    z = pulls(sub, expected)  # every point, the dark-limited far wings included
    assert np.all(np.abs(z) < 4.5), np.round(z, 2)
    chi2 = float(np.sum(z**2))
    assert stats.chi2.sf(chi2, len(z)) > 1e-3, (chi2, len(z))
    # the noise-equivalent BSDF: the signature's is what the bench adds, the bias of `plain`
    nebsdf = np.array(meta["bsdf_per_sr"], dtype=float)
    assert np.all(np.abs(plain.bsdf - sub.bsdf - nebsdf) <= 1e-9 * np.abs(plain.bsdf))
    assert np.all(np.array(meta["dark_floor_per_sr"]) > 0)
    readings = open_run(interleaved).readings()
    ranges = set(readings["range_w"][readings["kind"] == "sample"])
    assert sorted(meta["ranges"]) == sorted(f"{r:.6g}" for r in ranges)


def test_a_prompted_pass_waits_for_the_operator_and_subtracts_alike(tmp_path):
    from calibration.pipeline import reduce_run
    from gonio.store import open_run

    done = scan(tmp_path, {"pass": "prompted"}, stdin="c\n")
    assert done.returncode == 0, done.stderr
    assert "signature pass: remove the sample" in done.stderr
    run_dir = run_dir_of(done)
    kinds = open_run(run_dir).readings()["kind"]
    last_sample = int(np.flatnonzero(kinds == "sample")[-1])
    assert set(kinds[last_sample + 1:]) == {"signature", "dark", "beam"}  # one pass at the end
    sub = reduce_run(run_dir, subtract_signature=True)
    z = pulls(sub, truth(run_dir))
    assert np.all(np.abs(z) < 4.5), np.round(z, 2)


def test_a_prompted_pass_without_an_answer_aborts_before_it(tmp_path):
    from gonio.store import open_run

    done = scan(tmp_path, {"pass": "prompted", "arm_deg": [170.0, 190.0]}, stdin="")
    run = open_run(run_dir_of(done))
    assert run.meta["status"] == "aborted"
    assert "aborted by the user at: signature pass" in run.meta["reason"]
    assert "signature" not in set(run.readings()["kind"])


def test_gonio_reduce_reports_the_signature(interleaved):
    plain = gonio_cli("reduce", interleaved)
    assert plain.returncode == 0, plain.stderr
    assert f"signature: {len(THETA_O)} readings, not subtracted;" in plain.stdout
    assert "(left out; --subtract-signature keeps them)" in plain.stdout
    assert "dark floor 1/sr" in plain.stdout
    assert " 22      8       92.3" in plain.stdout  # points, valid, peak (the straight wings)
    csv = [ln for ln in (interleaved / "reduced.csv").read_text().splitlines()
           if not ln.startswith("#")]
    assert csv[0].endswith(",valid,flags") and sum(ln.endswith(",signature") for ln in csv) >= 6
    sub = gonio_cli("reduce", interleaved, "--subtract-signature", "--signature-share", "0.2")
    assert sub.returncode == 0, sub.stderr
    assert "subtracted; " in sub.stdout and "exceeds 20% of the net signal" in sub.stdout
    for verb in ("fit", "plot"):
        assert "--subtract-signature" in gonio_cli(verb, "--help").stdout
