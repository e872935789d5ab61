"""Exports of the model families' fits (calibration.exports.family_fit): a fit file's `family`
(microfacet where it names none); an ABg fit as an OpticStudio ABg catalog entry, read back by a
parser written here from the manual's fields and its BSDF formula; the Mitsuba material of a
Lambert fit (Mitsuba's diffuse) and of a diffuse-plus-lobe fit (the gonio_coated plugin),
evaluated, sampled and rendered by Mitsuba 3 itself, beside the measured mismatch of Mitsuba's
own roughplastic; every family tabulated as Zemax and ASTM; a family a format cannot hold
refused, naming the formats that take it."""

from __future__ import annotations

import json
import math
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from mitsuba_albedo import load_material, mitsuba_albedo, render_white_furnace
from mitsuba_llvm import llvm_mitsuba  # noqa: F401 (a fixture)

from calibration.exports.family_fit import family_fit, family_of
from calibration.exports.model import (
    astm_model_tables,
    load_fit,
    measured_zemax_files,
    mitsuba_files,
    zemax_files,
)
from calibration.exports.request import ExportRequest
from calibration.exports.writers import model_abg
from calibration.exports.zemax import read_zemax
from calibration.fit import FitResult
from calibration.synthetic import synthesize
from calibration.values import CalibrationError
from model.bsdf.families import make_family

#: One fit of each family, as `gonio fit --json` reports it (parameters by name).
FITS = {
    "lambert": ({"rho": 0.62}, {}),
    "oren-nayar": ({"rho": 0.7, "sigma": 0.35}, {}),
    "lambert+microfacet": ({"rho": 0.5, "alpha": 0.2, "eta": 1.5}, {"distribution": "ggx"}),
    "abg": ({"A": 2e-3, "B": 1e-4, "g": 1.8}, {}),
}
#: Mitsuba's roughplastic against gonio's lambert+microfacet (rms, max relative difference
#: over PAIRS): what docs/fitting.md reports.
ROUGHPLASTIC = [
    (("ggx", 0.02, 1.5, 0.5), (0.0261, 0.0339)),
    (("ggx", 0.05, 1.5, 0.5), (0.0502, 0.0899)),
    (("ggx", 0.1, 1.5, 0.5), (0.105, 0.19)),
    (("ggx", 0.3, 1.5, 0.8), (0.325, 0.445)),
    (("beckmann", 0.2, 1.5, 0.5), (0.088, 0.179)),
    (("ggx", 0.5, 1.8, 0.3), (0.50, 0.62)),
]


def fit_json(family: str, scale: float | None = None, chi2: float = 1.1) -> dict:
    """A family fit as `gonio fit --json` prints it."""
    values, settings = FITS[family]
    params = {n: {"value": v, "sigma": 0.01 * abs(v)} for n, v in values.items()}
    if scale is not None:
        params["scale"] = {"value": scale, "sigma": 0.01}
    return {"family": family, "distribution": settings.get("distribution"), "masking": None,
            "parameters": params, "chi2_dof_fit": chi2, "n_fit": 120, "chi2_dof_heldout": chi2,
            "n_heldout": 40}


def saved(tmp_path, fitted: dict):
    """The fit written as a `gonio fit --json` file, and loaded by the export's reader."""
    path = tmp_path / "fit.json"
    path.write_text(json.dumps(fitted) + "\n")
    return path, load_fit(path)


def directions(theta_deg, phi_deg=0.0) -> np.ndarray:
    """Unit vectors at polar angle theta, azimuth phi (deg)."""
    t, p = np.radians(theta_deg), np.radians(phi_deg)
    return np.stack(np.broadcast_arrays(np.sin(t) * np.cos(p), np.sin(t) * np.sin(p),
                                        np.cos(t)), axis=-1)


def test_a_fit_file_names_its_family_and_an_old_one_is_microfacet(tmp_path):
    old = {"distribution": "ggx", "masking": "separable",
           "parameters": {"alpha": {"value": 0.3, "sigma": 0.01},
                          "eta": {"value": 1.5, "sigma": 0.0, "fixed": True}},
           "chi2_dof_fit": 1.0, "n_fit": 50}
    assert family_of(saved(tmp_path, old)[1]) == "microfacet"
    assert family_fit(saved(tmp_path, old)[1]) is None
    result = saved(tmp_path, fit_json("lambert+microfacet", scale=0.9))[1]
    family = family_fit(result)
    assert (family.family, dict(family.values), family.scale) == (
        "lambert+microfacet", FITS["lambert+microfacet"][0], 0.9)
    assert family.settings == {"distribution": "ggx"}
    assert result.param("alpha") == (0.2, pytest.approx(0.002))


@pytest.mark.parametrize("change, said", [
    (dict(family="abg", parameters={"rho": {"value": 0.5}}), "the abg fit does not build"),
    (dict(family="glitter"), "family must be one of ('lambert', 'oren-nayar', "),
    (dict(parameters={"A": {"value": -1.0}, "B": {"value": 1e-3}, "g": {"value": 2.0}}),
     "A must be finite and in [0.0, inf]"),
])
def test_a_broken_family_fit_file_is_one_clear_error(tmp_path, change, said):
    with pytest.raises(CalibrationError) as error:
        saved(tmp_path, {**fit_json("abg"), **change})
    assert said in str(error.value) and "fit.json" in str(error.value)


# --- Zemax OpticStudio's ABg catalog entry ---------------------------------------------------

def parse_abg_entry(text: str) -> dict:
    """The entry's fields as the OpticStudio manual lists them (Name; Wave, um; rows of Use,
    Angle, A, B, g), from lines `Name n`, `Wave w`, `Row use angle A B g` (# comments)."""
    entry: dict = {"rows": []}
    for line in text.splitlines():
        key, *rest = line.split() or ["#"]
        if key == "Name":
            entry["name"] = rest[0]
        elif key == "Wave":
            entry["wave_um"] = float(rest[0])
        elif key == "Row":
            use, angle, a, b, g = rest
            entry["rows"].append({"use": use == "1", "angle": float(angle), "A": float(a),
                                  "B": float(b), "g": float(g)})
        else:
            assert key.startswith("#"), line
    return entry


def opticstudio_abg(row: dict, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """OpticStudio's ABg BSDF: A / (B + |beta - beta0|^g), beta the scattered direction's
    projection on the surface, beta0 the specular direction's (the incident one mirrored)."""
    specular = wi * np.array([-1.0, -1.0, 1.0])
    x = np.hypot(wo[..., 0] - specular[..., 0], wo[..., 1] - specular[..., 1])
    return row["A"] / (row["B"] + x ** row["g"])


@pytest.fixture(scope="module")
def reflection_data():
    """Reflection-only data at three incidences (their values do not matter here), at the
    HeNe wavelength."""
    data = synthesize("ggx", 0.3, incidences_deg=(0.0, 30.0, 60.0), sides=("reflection",))
    data.meta["wavelength_nm"] = 632.8
    return data


def test_an_abg_fit_is_opticstudios_abg_entry(reflection_data, tmp_path):
    path, result = saved(tmp_path, fit_json("abg", scale=1.25))
    paths, notes = model_abg(reflection_data, tmp_path / "black paint.abg", {},
                             ExportRequest(fit_file=path), "test")
    text = paths[0].read_text()
    entry = parse_abg_entry(text)
    values = FITS["abg"][0]
    assert entry["name"] == "BLACK_PAINT" and entry["wave_um"] == 0.6328 and notes == []
    (row,) = entry["rows"]
    assert row == {"use": True, "angle": 0.0, "A": 1.25 * values["A"], "B": values["B"],
                   "g": values["g"]}
    # OpticStudio's formula on the entry is the fitted model, scale included, at any pair
    model = make_family("abg", values)
    wi = directions(np.repeat([0.0, 20.0, 45.0, 70.0], 6), 180.0)
    wo = directions(np.tile([0.0, 5.0, 20.0, 44.0, 60.0, 85.0], 4), np.tile([0, 30, 90, 180,
                                                                             0, 270], 4))
    np.testing.assert_allclose(opticstudio_abg(row, wi, wo), 1.25 * model.eval(wi, wo),
                               rtol=1e-14)
    tis = 1.25 * model.total_integrated_scatter(directions(np.array([0.0, 30.0, 60.0, 85.0])))
    assert "TIS (hemispherical scatter of the fitted model) " + " / ".join(
        f"{x:.6g}" for x in tis) in text
    assert ("gonio fit of test: abg: A = 0.002 +- 2e-05, B = 0.0001 +- 1e-06, g = 1.8 +- "
            "0.018, scale = 1.25 +- 0.01; chi2/dof fitted 1.1") in text


def test_an_abg_entry_says_when_opticstudio_cannot_scale_or_scatters_too_much(
        reflection_data, tmp_path):
    data = reflection_data.subset(reflection_data.valid)
    data.meta.pop("wavelength_nm", None)
    fitted = fit_json("abg")
    fitted["parameters"]["A"]["value"] = 5.0
    paths, notes = model_abg(data, tmp_path / "x.abg", {},
                             ExportRequest(fit_file=saved(tmp_path, fitted)[0]))
    assert parse_abg_entry(paths[0].read_text())["wave_um"] == 0.0
    assert "Wave 0, so OpticStudio does not scale A and B" in paths[0].read_text()
    assert len(notes) == 1 and "OpticStudio needs TIS < 1" in notes[0]


@pytest.mark.parametrize("family, fmt, formats", [
    ("oren-nayar", "abg", "zemax or astm"),
    ("lambert", "abg", "mitsuba or zemax or astm"),
    ("oren-nayar", "mitsuba", "zemax or astm"),
    ("abg", "mitsuba", "abg or zemax or astm"),
])
def test_a_family_a_format_cannot_hold_is_refused_naming_those_that_can(
        reflection_data, tmp_path, family, fmt, formats):
    path, result = saved(tmp_path, fit_json(family))
    with pytest.raises(CalibrationError) as error:
        if fmt == "abg":
            model_abg(reflection_data, tmp_path / "x.abg", {}, ExportRequest(fit_file=path))
        else:
            mitsuba_files(result, tmp_path / "x.xml")
    assert str(error.value) == (f"export: --format {fmt} has no form of the {family} family; "
                                f"a {family} fit exports as --format {formats} (zemax and "
                                "astm tabulate it)")
    assert not list(tmp_path.glob("x.*"))


def test_a_microfacet_fit_is_no_abg_entry(reflection_data, tmp_path):
    old = {"distribution": "ggx", "masking": "separable",
           "parameters": {"alpha": {"value": 0.3, "sigma": 0.01},
                          "eta": {"value": 1.5, "sigma": 0.0, "fixed": True}},
           "chi2_dof_fit": 1.0, "n_fit": 50}
    with pytest.raises(CalibrationError, match="no form of the microfacet family; a "
                       "microfacet fit exports as --format mitsuba or zemax or astm"):
        model_abg(reflection_data, tmp_path / "x.abg", {},
                  ExportRequest(fit_file=saved(tmp_path, old)[0]))


# --- every family tabulated -------------------------------------------------------------------

def directional_albedo(family: str, values: dict, theta_deg: float) -> float:
    """The family's reflectance at incidence theta: closed forms where there are (Lambert's
    rho, the coat's a + rho (1 - a), ABg's TIS), else a 2^18-point Monte Carlo sum (sigma 1e-3)."""
    model = make_family(family, values, **FITS[family][1])
    wi = directions(np.array([theta_deg]))
    if family == "lambert":
        return values["rho"]
    if family == "lambert+microfacet":
        a = float(model.table(np.cos(np.radians(theta_deg))))
        return a + values["rho"] * (1.0 - a)
    if family == "abg":
        return float(model.total_integrated_scatter(wi)[0])
    u = np.random.default_rng(3).random((1 << 18, 3))
    return float(np.mean(model.sample(wi, u)[1]))


@pytest.mark.parametrize("family", sorted(FITS))
def test_every_family_tabulates_as_zemax_and_astm(reflection_data, tmp_path, family):
    values = FITS[family][0]
    result = saved(tmp_path, fit_json(family, scale=0.8))[1]
    model = make_family(family, values, **FITS[family][1])
    (path,) = zemax_files(reflection_data, result, tmp_path / "m.bsdf", "test")
    table = read_zemax(path)
    assert table.scatter_type == "BRDF" and list(table.angle_deg) == [0.0, 30.0, 60.0]
    assert f"gonio fit of test: {result.family}" in " ".join(table.comments)
    for a, theta_i in enumerate(table.angle_deg):
        wi = directions(np.array([theta_i]), 180.0)
        theta = theta_i - table.radial_deg  # azimuth 0: from the specular direction inward
        wo = np.stack([np.sin(np.radians(theta)), 0 * theta, np.cos(np.radians(theta))], axis=1)
        inside = np.abs(theta) < 89.9
        np.testing.assert_allclose(table.data[0, a, 0][inside],
                                   0.8 * model.eval(np.broadcast_to(wi, wo.shape), wo)[inside],
                                   rtol=1e-12)
        assert table.tis[0, a] == pytest.approx(0.8 * directional_albedo(family, values,
                                                                         theta_i), rel=3e-3)
    (astm,) = astm_model_tables(reflection_data, result, ["test"])
    wi = directions(np.degrees(astm.theta_i), np.degrees(astm.phi_i))
    wo = directions(np.degrees(astm.theta_s), np.degrees(astm.phi_s))
    np.testing.assert_allclose(astm.values[:, 0], 0.8 * model.eval(wi, wo), rtol=1e-12)
    (measured,) = measured_zemax_files(reflection_data, result, tmp_path / "r.bsdf")
    assert f"the fitted {family} (" in measured.read_text()


def test_a_family_fit_of_data_with_transmission_keeps_the_datas_index(tmp_path):
    """A family reflects only: the measured BTDF table keeps the data's index for its
    AngleOfIncidence (the refracted angle), and the model's BTDF is zero."""
    data = synthesize("ggx", 0.3, eta=1.51, incidences_deg=(0.0, 30.0))
    result = saved(tmp_path, fit_json("lambert"))[1]
    refracted = np.degrees(np.arcsin(np.sin(np.radians([0.0, 30.0])) / 1.51))
    measured = read_zemax(measured_zemax_files(data, result, tmp_path / "r.bsdf")[0])
    modelled = read_zemax(zemax_files(data, result, tmp_path / "m.bsdf")[0])
    for table in (measured, modelled):
        assert table.scatter_type == "BTDF"
        np.testing.assert_allclose(table.angle_deg, refracted, atol=1e-9)
    assert measured.data.max() > 0 and not modelled.data.any() and not modelled.tis.any()


# --- Mitsuba 3 --------------------------------------------------------------------------------

PAIRS_DEG = [(ti, to, phi) for ti in (0.0, 20.0, 40.0, 60.0, 75.0)
             for to in (0.0, 15.0, 30.0, 45.0, 60.0, 80.0) for phi in (0.0, 45.0, 90.0, 135.0,
                                                                        180.0)]


def mitsuba_f(mi, bsdf, toward_camera, toward_light) -> float:
    """Mitsuba's BSDF value (radiance mode) without its cosine factor."""
    si = mi.SurfaceInteraction3f()
    si.wi = mi.Vector3f(*toward_camera)
    si.sh_frame = mi.Frame3f(mi.Vector3f(0.0, 0.0, 1.0))
    value = bsdf.eval(mi.BSDFContext(mi.TransportMode.Radiance), si, mi.Vector3f(*toward_light))
    return float(value[0]) / float(toward_light[2])


def relative_differences(mi, bsdf, model, scale: float = 1.0) -> np.ndarray:
    """Mitsuba's value over gonio's, minus 1, at PAIRS_DEG, with either direction the camera."""
    out = []
    for ti, to, phi in PAIRS_DEG:
        wi, wo = directions(ti, 180.0), directions(to, phi)
        gonio = scale * float(model.eval(wi, wo))
        out += [mitsuba_f(mi, bsdf, wo, wi) / gonio - 1, mitsuba_f(mi, bsdf, wi, wo) / gonio - 1]
    return np.array(out)


@pytest.fixture(scope="module")
def mi():
    """Mitsuba 3 (the `mitsuba` extra, in `test`)."""
    return pytest.importorskip("mitsuba", reason="Mitsuba 3 is the `mitsuba` extra (in `test`)")


def test_a_lambert_fit_is_mitsubas_diffuse(mi, tmp_path):
    paths, notes = mitsuba_files(saved(tmp_path, fit_json("lambert", scale=0.9))[1],
                                 tmp_path / "matte.xml")
    assert [p.name for p in paths] == ["matte.xml"] and notes == []
    assert ET.parse(paths[0]).getroot().find("bsdf").get("type") == "diffuse"
    bsdf = load_material(paths[0], "scalar_rgb")
    error = relative_differences(mi, bsdf, make_family("lambert", {"rho": 0.62}), 0.9)
    assert np.abs(error).max() < 1e-6


def coated_fit(tmp_path, distribution: str, alpha: float, eta: float, rho: float,
               scale: float | None = None) -> FitResult:
    """A lambert+microfacet fit of these values, as a fit file gives it."""
    fitted = fit_json("lambert+microfacet", scale)
    fitted["distribution"] = distribution
    fitted["parameters"].update({"alpha": {"value": alpha}, "eta": {"value": eta},
                                 "rho": {"value": rho}})
    return saved(tmp_path, fitted)[1]


@pytest.mark.parametrize("case, expected", ROUGHPLASTIC,
                         ids=[f"{c[0]}-{c[1]}-{c[2]}-{c[3]}" for c, _ in ROUGHPLASTIC])
def test_the_coated_plugin_is_gonios_model_and_roughplastic_is_not(mi, tmp_path, case,
                                                                    expected):
    distribution, alpha, eta, rho = case
    result = coated_fit(tmp_path, distribution, alpha, eta, rho, scale=0.95)
    paths, notes = mitsuba_files(result, tmp_path / "paint.xml", "test")
    assert [p.name for p in paths] == ["paint.xml", "gonio_mitsuba_plugin.py"] and notes == []
    root = ET.parse(paths[0]).getroot().find("bsdf")
    assert root.get("type") == "gonio_coated" and root.find("bsdf").get("type") == "roughplastic"
    text = paths[0].read_text()
    assert "roughplastic with this base is darker than the model" in text
    assert "gonio_mitsuba_plugin.register()" in text
    model = make_family("lambert+microfacet", {"rho": rho, "alpha": alpha, "eta": eta},
                        distribution=distribution)
    error = relative_differences(mi, load_material(paths[0], "scalar_rgb"), model, 0.95)
    # float32 and the same albedo table; Mitsuba's Beckmann lobe is within 0.6 % of gonio's
    assert np.abs(error).max() < (2e-5 if distribution == "ggx" else 5e-3)
    plastic = mi.load_dict({"type": "roughplastic", "distribution": distribution,
                            "alpha": alpha, "int_ior": eta, "ext_ior": 1.0,
                            "diffuse_reflectance": {"type": "rgb", "value": [rho] * 3}})
    plastic_error = relative_differences(mi, plastic, model)
    rms, worst = math.sqrt(np.mean(plastic_error ** 2)), np.abs(plastic_error).max()
    assert (rms, worst) == pytest.approx(expected, rel=0.02)


def test_a_coat_fitted_with_correlated_masking_says_mitsuba_masks_separably(tmp_path):
    fitted = fit_json("lambert+microfacet")
    fitted["masking"] = "correlated"
    result = saved(tmp_path, fitted)[1]
    assert family_fit(result).settings == {"distribution": "ggx", "masking": "correlated"}
    paths, _ = mitsuba_files(result, tmp_path / "paint.xml")
    assert ("the fit's coat used correlated masking; Mitsuba's roughplastic uses separable "
            "Smith") in paths[0].read_text()


@pytest.mark.conformance
@pytest.mark.usefixtures("llvm_mitsuba")
def test_mitsuba_samples_and_renders_the_coated_plugin(tmp_path):
    rho, alpha, eta = 0.8, 0.3, 1.5
    paths, _ = mitsuba_files(coated_fit(tmp_path, "ggx", alpha, eta, rho), tmp_path / "p.xml")
    bsdf = load_material(paths[0])
    model = make_family("lambert+microfacet", {"rho": rho, "alpha": alpha, "eta": eta})
    for theta in (0.0, 30.0, 60.0, 85.0):
        r, t, sigma = mitsuba_albedo(bsdf, theta, 1 << 18)
        a = float(model.table(math.cos(math.radians(theta))))
        assert t == 0.0 and abs(r - (a + rho * (1.0 - a))) < 4 * sigma + 1e-3
    image = render_white_furnace(paths[0])
    # a painted sphere in a white furnace: it reflects a(i) + rho (1 - a(i)) of what comes in
    assert image.shape == (16, 16, 3) and np.isfinite(image).all()
    assert 0.5 < image.min() and image.mean() < 1.0


@pytest.mark.parametrize("family, truth, settings, held", [
    ("lambert+microfacet", {"rho": 0.5, "alpha": 0.15, "eta": 1.5}, {"distribution": "ggx"},
     {"eta": 1.5}),  # the coat's index held at the sample's
    ("lambert", {"rho": 0.6}, {}, {"rho": 0.8}),  # relative: rho held, the scale the level
])
def test_a_family_fit_with_held_parameters_exports_its_whole_model(tmp_path, family, truth,
                                                                   settings, held):
    from calibration.fit import FitOptions, select
    from calibration.synthetic import synthesize_family

    relative = family == "lambert"
    data = synthesize_family(family, truth, settings, seed=3, scale=0.2 if relative else 1.0)
    result = select(data, FitOptions(families=(family,), distributions=("ggx",),
                                     fit_scale=relative, fit_incidence_deg=None))
    assert result.fixed == held
    loaded = saved(tmp_path, result.to_dict())[1]
    exported = family_fit(loaded)
    fitted = {n: float(v) for n, v in zip(result.names, result.values, strict=True)
              if n != "scale"}
    assert dict(exported.values) == pytest.approx({**fitted, **held}, rel=1e-12)
    assert dict(exported.settings) == {k: v for k, v in result.settings.items() if v}
    wi, wo = directions(30.0), directions(np.array([0.0, 20.0, 45.0]), 180.0)
    np.testing.assert_allclose(exported.point_model()(wi, wo),
                               result.scale * result.model().eval(wi, wo), rtol=1e-12)
