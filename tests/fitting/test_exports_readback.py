"""Zemax tabular BSDF and Mitsuba 3 exports of a fit, each read back with our own reader and
checked against the model by independent routes (in-plane geometry, Monte Carlo TIS)."""

import math

import numpy as np
import pytest
from mitsuba_reader import read_mitsuba
from zemax_cells import table_tis

from calibration.exports.model import mitsuba_files, zemax_files
from calibration.exports.zemax import read_zemax
from calibration.fit import FitOptions, fit
from calibration.synthetic import synthesize
from calibration.values import CalibrationError


@pytest.fixture(scope="module")
def ground_glass():
    data = synthesize("ggx", 0.394, seed=21, incidences_deg=(0.0, 30.0, 60.0))
    return data, fit(data, FitOptions(distributions=("ggx", "beckmann")))


def test_zemax_btdf_and_brdf_read_back(ground_glass, tmp_path):
    data, result = ground_glass
    paths = zemax_files(data, result, tmp_path / "glass.bsdf", source="synthetic")
    assert [p.name for p in paths] == ["glass.bsdf", "glass-BRDF.bsdf"]
    btdf, brdf = read_zemax(paths[0]), read_zemax(paths[1])
    assert (btdf.scatter_type, brdf.scatter_type) == ("BTDF", "BRDF")
    assert btdf.symmetry == "PlaneSymmetrical" and btdf.azimuth_deg[-1] == 180.0
    np.testing.assert_allclose(brdf.angle_deg, [0.0, 30.0, 60.0])
    refracted = np.degrees(np.arcsin(np.sin(np.radians([0.0, 30.0, 60.0])) / result.eta))
    np.testing.assert_allclose(btdf.angle_deg, refracted, atol=1e-5)
    assert any("ggx" in c for c in btdf.comments)
    model = result.model()
    for table, sign in ((brdf, 1.0), (btdf, -1.0)):
        for a, theta_i in enumerate([0.0, 30.0, 60.0]):
            ti = math.radians(theta_i)
            wi = np.array([-math.sin(ti), 0.0, math.cos(ti)])
            spec = math.radians(table.angle_deg[a])
            r = np.radians(table.radial_deg)
            # azimuth 0 turns toward the normal, 180 away from it, in the plane of incidence
            for az, theta in ((0, spec - r), (len(table.azimuth_deg) - 1, spec + r)):
                wo = np.stack([np.sin(theta), 0 * theta, sign * np.cos(theta)], axis=1)
                ok = (np.abs(theta) < math.pi / 2 - 1e-6)
                expected = np.where(ok, model.eval(np.broadcast_to(wi, wo.shape), wo), 0.0)
                np.testing.assert_allclose(table.data[0, a, az], expected, rtol=2e-6,
                                           atol=1e-12)


def test_zemax_tis_matches_monte_carlo_and_the_table(ground_glass, tmp_path):
    data, result = ground_glass
    paths = zemax_files(data, result, tmp_path / "glass.bsdf")
    model = result.model()
    rng = np.random.default_rng(5)
    for path, side in ((paths[0], -1.0), (paths[1], 1.0)):
        table = read_zemax(path)
        for a, theta_i in enumerate([0.0, 30.0, 60.0]):
            ti = math.radians(theta_i)
            n = 200_000
            wi = np.broadcast_to([-math.sin(ti), 0.0, math.cos(ti)], (n, 3))
            wo, weight, _ = model.sample(wi, rng.uniform(size=(n, 3)))
            hit = weight * (side * wo[:, 2] > 0)
            mc, mc_err = hit.mean(), hit.std() / math.sqrt(n)
            assert abs(table.tis[0, a] - mc) < 4 * mc_err + 1e-4
            assert table_tis(table, 0, a) == pytest.approx(table.tis[0, a], rel=0.03)


def test_zemax_reader_names_the_bad_line(ground_glass, tmp_path):
    data, result = ground_glass
    path = zemax_files(data.subset(~data.transmission), result, tmp_path / "r.bsdf")[0]
    text = path.read_text().splitlines()
    k = next(i for i, ln in enumerate(text) if ln.startswith("ScatterRadial"))
    text[k] = "ScatterRadial  3"
    path.write_text("\n".join(text))
    with pytest.raises(CalibrationError, match=rf"r.bsdf:{k + 2}: ScatterRadial: 3 values"):
        read_zemax(path)


def test_mitsuba_roughdielectric_reads_back(ground_glass, tmp_path):
    _, result = ground_glass
    back = read_mitsuba(mitsuba_files(result, tmp_path / "glass.xml")[0][0])
    assert back["type"] == "roughdielectric" and back["version"] == "3.0.0"
    assert back["params"]["distribution"] == "ggx"
    assert back["params"]["alpha"] == pytest.approx(result.alpha, rel=1e-8)
    assert back["params"]["int_ior"] == pytest.approx(1.51)
    assert back["params"]["ext_ior"] == 1.0
    assert "specular_transmittance" not in back["params"]


def test_mitsuba_phong_scaled_fit_becomes_beckmann_with_a_note(tmp_path):
    data = synthesize("phong", 0.2, seed=4, incidences_deg=(0.0, 30.0))
    data.bsdf *= 0.8
    data.sigma *= 0.8
    result = fit(data, FitOptions(distributions=("phong",), fit_scale=True,
                                  fit_incidence_deg=None))
    path = mitsuba_files(result, tmp_path / "phong.xml")[0][0]
    back = read_mitsuba(path)
    assert back["params"]["distribution"] == "beckmann"
    assert back["params"]["specular_reflectance"] == pytest.approx(result.scale, rel=1e-8)
    assert result.scale == pytest.approx(0.8, abs=4 * result.param("scale")[1])
    assert "no Phong distribution" in path.read_text()


def test_anisotropic_fit_exports(tmp_path):
    data = synthesize("ggx", 0.394, seed=6, incidences_deg=(0.0, 30.0))
    result = fit(data, FitOptions(distributions=("ggx",), anisotropic=True))
    ax, ay = result.alpha
    table = read_zemax(zemax_files(data, result, tmp_path / "a.bsdf")[0])
    assert table.symmetry == "Asymmetrical" and table.azimuth_deg[-2:].tolist() == [350.0, 360.0]
    assert table_tis(table, 0, 0) == pytest.approx(table.tis[0, 0], rel=0.03)
    params = read_mitsuba(mitsuba_files(result, tmp_path / "a.xml")[0][0])["params"]
    assert (params["alpha_u"], params["alpha_v"]) == (pytest.approx(ax), pytest.approx(ay))
    assert "alpha" not in params


def test_conductor_fit_and_roughconductor_export(tmp_path):
    from calibration.reduced import ReducedData
    from calibration.synthetic import in_plane_directions
    from model.bsdf import RoughConductor

    parts = [in_plane_directions(t, 1.0, 0.2, sides=("reflection",)) for t in (0.0, 40.0)]
    wi, wo = (np.concatenate([p[k] for p in parts]) for k in range(2))
    f = RoughConductor("ggx", 0.2, eta_complex=complex(0.2, 3.6)).eval(wi, wo)
    sigma = 0.02 * f + f.max() * 1e-6
    measured = f + sigma * np.random.default_rng(3).standard_normal(len(f))
    data = ReducedData(wi, wo, measured, sigma, np.ones(len(f), bool), np.zeros(len(f), bool),
                       {"eta": 0.2, "k": 3.6, "kind": "conductor"})
    result = fit(data, FitOptions(distributions=("ggx", "beckmann")))
    value, sigma_alpha = result.param("alpha")
    assert result.distribution == "ggx" and result.k == 3.6
    assert abs(value - 0.2) < 3 * sigma_alpha and result.chi2_dof_heldout < 1.5
    back = read_mitsuba(mitsuba_files(result, tmp_path / "metal.xml")[0][0])
    assert back["type"] == "roughconductor"
    assert (back["params"]["eta"], back["params"]["k"]) == (pytest.approx(0.2), 3.6)
