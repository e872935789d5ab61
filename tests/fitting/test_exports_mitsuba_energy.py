"""The Mitsuba export of a multiple-scattering fit carries its energy: Mitsuba 3 itself,
sampling the exported material (the gonio_multiscatter plugin written beside the XML), gives
the fitted model's reflectance R and transmittance T at 0, 30, 60 and 85 deg incidence
(calibration.exports.mitsuba_energy), and renders a scene with it; without the plugin
(--single-scattering) the material keeps the share of R + T the export states; where the
plugin cannot match the model the export refuses."""

from __future__ import annotations

import dataclasses
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from mitsuba_albedo import load_material, mitsuba_albedo, render_white_furnace
from mitsuba_llvm import llvm_mitsuba  # noqa: F401 (a fixture)

from calibration.exports import mitsuba_energy
from calibration.exports.mitsuba import PLUGIN_TABLES
from calibration.exports.model import mitsuba_files
from calibration.fit import FitResult
from calibration.values import CalibrationError

ANGLES = mitsuba_energy.REPORT_ANGLES_DEG
SAMPLES = 1 << 18  # per incidence; the standard error of R + T is about 2e-4


def multiple_scattering_fit(alpha: float, masking: str, **changes) -> FitResult:
    """A GGX glass fit (eta 1.51) that used multiple scattering, as `gonio fit` returns it."""
    result = FitResult(distribution="ggx", masking=masking, names=("alpha",),
                       values=np.array([alpha]), errors=np.array([0.01]), covariance=np.eye(1),
                       eta=1.51, k=None, chi2_dof_fit=1.0, n_fit=40, chi2_dof_heldout=1.1,
                       n_heldout=20, preferred_by=None, walks=64)
    return dataclasses.replace(result, **changes)


@pytest.fixture(scope="module", params=[
    dict(alpha=0.394, masking="separable"), dict(alpha=0.553, masking="correlated"),
    dict(alpha=0.3, masking="separable", eta=0.2, k=3.6)],
    ids=["ground-glass-separable", "acid-etched-correlated", "metal"])
def exported(request, tmp_path_factory):
    """A multiple-scattering fit, its export (XML and plugin) and the model's albedo."""
    params = dict(request.param)
    result = multiple_scattering_fit(params.pop("alpha"), params.pop("masking"), **params)
    out = tmp_path_factory.mktemp("mitsuba") / "glass.xml"
    paths, notes = mitsuba_files(result, out, "test")
    return result, paths, notes, mitsuba_energy.model_albedo(result, np.array(ANGLES))


def test_export_writes_the_plugin_beside_the_xml(exported):
    result, paths, notes, _ = exported
    assert [p.name for p in paths] == ["glass.xml", "gonio_mitsuba_plugin.py"] and notes == []
    root = ET.parse(paths[0]).getroot()
    bsdf = root.find("bsdf")
    assert bsdf.get("type") == "gonio_multiscatter"
    single = "roughdielectric" if result.k is None else "roughconductor"
    assert bsdf.find("bsdf").get("type") == single
    names = {e.get("name") for e in bsdf.findall("string")}
    assert set(PLUGIN_TABLES) <= names
    text = paths[0].read_text()
    assert "gonio_mitsuba_plugin.register()" in text and "R + T is within" in text


@pytest.mark.conformance
@pytest.mark.usefixtures("llvm_mitsuba")
def test_mitsuba_albedo_of_the_export_matches_the_model(exported):
    result, paths, _, model = exported
    bsdf = load_material(paths[0])
    for k, theta in enumerate(ANGLES):
        r, t, err = mitsuba_albedo(bsdf, theta, SAMPLES)
        r_model, t_model = model.outside[0][k], model.outside[1][k]
        total = r_model + t_model
        assert abs(r + t - total) + 4 * err < mitsuba_energy.MAX_ALBEDO_ERROR * total, theta
        # R and T apart: the plugin's tables are the model's, so only noise separates them
        assert abs(r - r_model) < 4 * err + 0.003 and abs(t - t_model) < 4 * err + 0.003


@pytest.mark.conformance
@pytest.mark.usefixtures("llvm_mitsuba")
def test_single_scattering_export_states_what_it_drops(exported, tmp_path):
    result, _, _, model = exported
    paths, notes = mitsuba_files(result, tmp_path / "single.xml", "test",
                                 single_scattering=True)
    assert [p.name for p in paths] == ["single.xml"] and len(notes) == 1
    assert notes[0] in paths[0].read_text()
    kept = [float(x) for x in notes[0].split("keeps ")[1].split(" of")[0].split(" / ")]
    bsdf = load_material(paths[0])
    for k, theta in enumerate(ANGLES):
        r, t, err = mitsuba_albedo(bsdf, theta, SAMPLES)
        total = model.outside[0][k] + model.outside[1][k]
        assert (r + t) / total == pytest.approx(kept[k], abs=4 * err + 1e-3)
    assert max(kept) < 1.0
    if result.k is None:  # glass: the 60 deg light the plugin restores is not negligible
        assert kept[2] < 0.95


def test_the_plugin_reads_the_tables_the_writer_names():
    from calibration.exports import mitsuba_plugin

    assert mitsuba_plugin.TABLES == PLUGIN_TABLES


def test_the_walks_split_conserves_the_energy_energy_loss_gives():
    """orders >= 2 of a dielectric carry what order 1 loses: the walk's R + T (counted, with
    its Monte Carlo error) agrees with energy_loss (quadrature) that the tables scale to."""
    from model.bsdf import RoughDielectric

    result = multiple_scattering_fit(0.553, "correlated")
    single = RoughDielectric("ggx", 0.553, 1.51, masking="correlated")
    for theta in (0.0, 60.0, 85.0):
        r_ms, t_ms = mitsuba_energy.higher_orders_albedo(result, theta, True)
        r_1, t_1 = mitsuba_energy.single_albedo(single, theta, True)
        assert r_1 + t_1 + r_ms + t_ms == pytest.approx(1.0, abs=2e-3)


def test_anisotropic_multiple_scattering_fit_is_refused_unless_single_scattering(tmp_path):
    result = multiple_scattering_fit(0.3, "separable", names=("alpha_x", "alpha_y"),
                                     values=np.array([0.3, 0.5]), errors=np.array([0.01, 0.01]),
                                     covariance=np.eye(2))
    with pytest.raises(CalibrationError, match=r"anisotropic surface; pass --single-scattering "
                                               r"to write the single-scattering material"):
        mitsuba_files(result, tmp_path / "a.xml")
    assert not (tmp_path / "a.xml").exists()
    paths, notes = mitsuba_files(result, tmp_path / "a.xml", single_scattering=True)
    assert notes[0].startswith("single scattering only: the material drops the fit's multiple "
                               "scattering and keeps ")
    assert notes[0].endswith(" of the model's R + T at 0 / 30 / 60 / 85 deg incidence")


def test_a_material_the_plugin_cannot_match_is_refused(tmp_path, monkeypatch):
    monkeypatch.setattr(mitsuba_energy, "MAX_ALBEDO_ERROR", 1e-9)
    with pytest.raises(CalibrationError, match=r"R \+ T is .* % from the model's at .* deg "
                                               r"\(more than 1e-07 %\); pass "
                                               r"--single-scattering"):
        mitsuba_files(multiple_scattering_fit(0.394, "separable"), tmp_path / "g.xml")
    assert not (tmp_path / "g.xml").exists()


@pytest.mark.conformance
@pytest.mark.usefixtures("llvm_mitsuba")
def test_mitsuba_renders_a_scene_with_the_export(exported):
    _, paths, _, _ = exported
    image = render_white_furnace(paths[0])
    # a glass sphere in a white furnace: every pixel sees light, none more than comes in
    assert image.shape == (16, 16, 3) and np.isfinite(image).all()
    assert 0.5 < image.min() and image.mean() < 1.05
