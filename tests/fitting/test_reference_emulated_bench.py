"""Relative against absolute calibration of the same emulated sample (real ptys, the ESP and PM100
emulators, the scan engine, the real CLI): the white reference panel and Walter's ground glass
(its reflection side) scanned at the same geometry on a bench whose aperture is 0.3 % wider
than its [optics] states (within the stated tolerance); `gonio calibrate build --reference`
with the panel's certificate recovers the true aperture's solid angle, and the ground glass
reduced once absolutely (beam and nominal aperture) and once against the reference agrees at
every point within U, the relative U carrying the certificate's term."""

from __future__ import annotations

import json
import math
import tomllib

import numpy as np
import pytest
from fitting_bench_runs import ROOT, instrument, plan, scan

from calibration import calfile
from calibration.aperture import from_geometry
from calibration.budget import expanded
from calibration.pipeline import reduce_run
from gonio.store import open_run
from gonio_cli.main import main

CERTIFICATE = ROOT / "examples" / "certificates" / "white-reference.toml"
#: The bench's aperture and what its [optics] states of it (10 mm +- 0.05 mm).
TRUE_DIAMETER_MM, DISTANCE_MM = 10.03, 500.0
OPTICS = {"aperture_diameter_mm": 10.0, "aperture_distance_mm": DISTANCE_MM,
          "aperture_diameter_tolerance_mm": 0.05}
GRID = [{"side": "reflection", "theta_i_deg": 30.0,
         "theta_o_deg": {"start": -70.0, "stop": 70.0, "step": 10.0}, "skip_forbidden": True}]
PANEL = {"id": "white-reference", "kind": "reference"}
GLASS = {"id": "ground-glass", "kind": "hemisphere", "eta": 1.51}


def panel_truth() -> dict:
    """The [sim.sample] of the panel the example certificate certifies: its Lambert rho."""
    cert = tomllib.loads(CERTIFICATE.read_text())
    return {"kind": "reference", "family": "lambert", "rho": cert["point"][0]["value"]}


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """(reference run, sample run) on the same bench, at the same geometry."""
    tmp = tmp_path_factory.mktemp("reference")
    aperture = {"diameter_mm": TRUE_DIAMETER_MM, "distance_mm": DISTANCE_MM}
    out = []
    for name, truth, sample in (
            ("panel", panel_truth(), PANEL),
            ("glass", {"kind": "hemisphere", "distribution": "ggx", "alpha": 0.394,
                       "eta": 1.51, "multiple_scattering": False}, GLASS)):
        cfg = instrument(tmp, {"sample": truth, "aperture": aperture}, optics=OPTICS, seed=3)
        # instrument() takes the bench's aperture as [optics] states it: this one differs
        text = cfg.read_text()
        assert "\n[sim.aperture]\n" in text
        cfg.write_text(text.replace("\n[sim.aperture]\n", "\n[sim.aperture]\n" + "".join(
            f"{key} = {value}\n" for key, value in aperture.items())))
        p = plan(tmp, name, GRID, dark_every=8, beam_every=8, sample=sample)
        out.append(scan(p, cfg, tmp / "runs"))
    return out


def test_relative_and_absolute_results_of_the_same_sample_agree_within_u(runs, tmp_path,
                                                                         capsys):
    reference_run, sample_run = runs
    cal_path = tmp_path / "ref-cal.json"
    assert main(["calibrate", "build", str(reference_run), "--reference", str(CERTIFICATE),
                 "--out", str(cal_path)]) == 0
    assert capsys.readouterr().out.strip() == str(cal_path)
    ref = calfile.load(cal_path).reference
    # the certificate it came from, by id and digest
    written = json.loads(cal_path.read_text())["reference"]["certificate"]
    assert written["id"] == tomllib.loads(CERTIFICATE.read_text())["id"]
    assert len(written["sha256"]) == 64 and ref.chi2_dof < 3.0
    # the effective solid angle is the bench's true aperture (the certificate states the
    # panel's truth), not the nominal one 0.6 % smaller
    true_omega = from_geometry(0.5e-3 * TRUE_DIAMETER_MM, 1e-3 * DISTANCE_MM)
    assert abs(ref.solid_angle_sr.pull(true_omega)) < 4.0
    assert ref.solid_angle_sr.value / ref.nominal_solid_angle_sr == pytest.approx(1.006,
                                                                                  abs=0.002)

    absolute = reduce_run(open_run(sample_run))
    relative = reduce_run(open_run(sample_run), cal_path)
    ok = absolute.valid & relative.valid
    assert ok.sum() >= 12
    _, big_u_abs = expanded(absolute)
    _, big_u_rel = expanded(relative)
    # En = |difference| / sqrt(U_abs^2 + U_rel^2) <= 1 at every point (ISO 13528's criterion),
    # and the absolute U alone covers the difference: its aperture term covers the 0.6 %
    difference = np.abs(relative.bsdf - absolute.bsdf)[ok]
    assert np.all(difference <= np.hypot(big_u_abs[ok], big_u_rel[ok]))
    assert np.all(difference < big_u_abs[ok])
    # the relative U carries the certificate's term (0.005 on R = 0.99, k = 2) and the
    # reference run's, shared by every point, in place of the aperture tolerance's
    rel_u = relative.components["reference_certificate"][ok] / relative.bsdf[ok]
    np.testing.assert_allclose(rel_u, 0.005 / 0.99 / 2.0, rtol=1e-9)  # U / R / k
    assert {"reference_certificate", "reference_run"} <= set(relative.meta["budget"]["shared"])
    assert "solid_angle" in absolute.components and "solid_angle" not in relative.components
    assert relative.meta["reference"]["certificate"]["sha256"] == written["sha256"]
    # the relative values are nearer the truth: the absolute ones carry the aperture's 0.6 %
    ratio = np.median(absolute.bsdf[ok] / relative.bsdf[ok])
    assert ratio == pytest.approx(ref.scale.value, rel=1e-9)
    assert math.isclose(ratio, 1.006, abs_tol=0.002)
    # gonio reduce says what it normalised to, and the budget's shared reference terms
    assert main(["reduce", str(sample_run), "--calibration", str(cal_path), "--out",
                 str(tmp_path / "reduced.csv")]) == 0
    said = capsys.readouterr().out
    assert f"normalised to the reference {written['id']} (run {reference_run})" in said
    assert "reference_certificate shared" in said and "reference_run        shared" in said


def test_a_reference_run_needs_its_certificate_and_a_certificate_its_run(runs, tmp_path,
                                                                         capsys):
    reference_run, sample_run = runs
    out = tmp_path / "cal.json"
    assert main(["calibrate", "build", str(reference_run), "--out", str(out)]) == 2
    assert 'measures a reference panel (its [sample] kind = "reference"): give its ' \
           "certificate with --reference CERT.toml" in capsys.readouterr().err
    assert main(["calibrate", "build", str(sample_run), "--reference", str(CERTIFICATE),
                 "--out", str(out)]) == 2
    assert "--reference needs exactly one run of the reference panel" in capsys.readouterr().err
    assert not out.exists()
