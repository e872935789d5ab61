"""Exports of measured (reduced) data and their imports: each format written, read back and
compared; CF-1.8 checked by the CF checker (cfchecker, offline with the tables in
tests/fitting/cf_tables) and read with xarray; the ASTM layout parsed as libbsdf's AstmReader
parses it; the measured Zemax table holds the data where measured, its TIS uncertainty checked
by Monte Carlo; import then fit recovers the parameters of data gonio generated."""

from __future__ import annotations

import csv
import json
import math
from dataclasses import replace
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
import pytest
import xarray
from cf_kit import cf_counts
from zemax_cells import assert_measured_cells, table_tis

from calibration.exports import ExportRequest
from calibration.exports.astm import astm_tables, write_astm
from calibration.exports.cf import read_reduced_netcdf, write_raw_netcdf, write_reduced_netcdf
from calibration.exports.measured import shared_error_lines, write_reduced_csv
from calibration.exports.model import measured_zemax_files, zemax_files
from calibration.exports.run_files import write_data
from calibration.exports.zemax import read_zemax, turned, write_zemax
from calibration.exports.zemax_measured import measured_nodes, measured_table
from calibration.fit import FitOptions, fit
from calibration.imports import ImportOptions, read_measured
from calibration.reduced import ReducedData
from calibration.synthetic import synthesize
from calibration.values import CalibrationError
from gonio.record import record_lines
from gonio.store import READING_DTYPE
from gonio_cli.main import main

RECORD = {"run": "synthetic", "started_utc": "2026-12-02T00:20:05.757+00:00",
          "wavelength_nm": 632.8, "sample": {"id": "GG-7", "eta": 1.51}}
ALPHA = 0.394


def glass_data(seed: int = 3):
    """Synthetic ground glass (GGX alpha 0.394, both sides, 0 and 30 deg), with two budget
    components, flags, a few invalid points and a shared relative error."""
    data = synthesize("ggx", ALPHA, incidences_deg=(0.0, 30.0), n_uniform=24, n_peak=12,
                      seed=seed)
    data.meta["wavelength_nm"] = 632.8
    data.components = {"read": 0.6 * data.sigma, "beam": 0.8 * data.sigma}
    data.flags[::7] = "signature"
    data.valid[5::11] = False
    return data


@pytest.fixture(scope="module")
def glass():
    data = glass_data()
    return data, fit(data, FitOptions(distributions=("ggx",)))


def test_reduced_csv_round_trip(glass, tmp_path):
    data, _ = glass
    path = write_reduced_csv(data, tmp_path / "r.csv", ["run: \"synthetic\""])
    back = read_measured(path)
    np.testing.assert_allclose(back.wi, data.wi, atol=1e-12)
    np.testing.assert_allclose(back.wo, data.wo, atol=1e-12)
    np.testing.assert_array_equal(back.bsdf, data.bsdf)
    np.testing.assert_array_equal(back.sigma, data.sigma)
    np.testing.assert_array_equal(back.valid, data.valid)
    np.testing.assert_array_equal(back.transmission, data.transmission)
    np.testing.assert_array_equal(back.flags, data.flags)
    assert set(back.components) == {"read", "beam"}
    np.testing.assert_array_equal(back.components["beam"], data.components["beam"])
    assert back.meta["eta"] == 1.51 and back.meta["wavelength_nm"] == 632.8
    rows = list(csv.DictReader(ln for ln in path.read_text().splitlines()
                               if not ln.startswith("#")))
    assert [float(r["U"]) for r in rows] == pytest.approx(2.0 * data.sigma, rel=1e-15)
    assert float(rows[0]["k"]) == 2.0
    to = np.array([float(r["theta_o_deg"]) for r in rows])
    assert np.all((to > 90.0) == data.transmission)  # transmission: theta_o above 90


def test_plain_csv_columns_assumptions_and_errors(glass, tmp_path, capsys):
    data, _ = glass
    good = data.subset(data.valid)
    path = tmp_path / "plain.csv"
    rows = ["theta_i,phi_i,theta_o,phi_o,bsdf"]
    for wi, wo, f in zip(good.wi, good.wo, good.bsdf, strict=True):
        ti, to = (math.degrees(math.acos(w[2])) for w in (wi, wo))
        pi, po = (math.degrees(math.atan2(w[1], w[0])) for w in (wi, wo))
        rows.append(",".join(repr(float(v)) for v in (ti, pi, to, po, f)))
    path.write_text("\n".join(rows) + "\n")
    with pytest.raises(CalibrationError, match=r"plain.csv: 2 inputs missing: \(1\) the CSV has "
                                               r"no uncertainties.*--sigma-relative.*; \(2\) "
                                               r"the file gives no refractive index.*--eta"):
        read_measured(path)
    with pytest.raises(CalibrationError, match=r"plain.csv: the file gives no refractive "
                                               r"index \(eta\).*--eta"):
        read_measured(path, ImportOptions(sigma_relative=0.02))
    back = read_measured(path, ImportOptions(eta=1.51, sigma_relative=0.02))
    np.testing.assert_allclose(back.wo, good.wo, atol=1e-12)
    np.testing.assert_allclose(back.sigma, 0.02 * np.abs(good.bsdf), rtol=1e-12)
    assert "assumed: u = 0.02 * |bsdf|" in back.meta["noise_model"]
    assert main(["fit", "--import", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "plain.csv: 2 inputs missing: (1) the CSV has no " in err
    # a value of 0 gets no u from a relative assumption: left out and flagged, not weighed
    # with a vanishing sigma
    path.write_text("theta_i_deg,phi_i_deg,theta_o_deg,phi_o_deg,bsdf\n"
                    "0,0,10,0,0.5\n0,0,20,0,0.0\n0,0,30,0,0.2\n")
    zeros = read_measured(path, ImportOptions(eta=1.51, sigma_relative=0.02))
    assert zeros.valid.tolist() == [True, False, True]
    assert list(zeros.flags) == ["", "zero", ""]
    path.write_text("theta_i_deg,phi_i_deg,theta_o_deg,bsdf\n0,0,10,1\n")
    with pytest.raises(CalibrationError, match=r"plain.csv: no column phi_o"):
        read_measured(path)
    path.write_text("theta_i_deg,phi_i_deg,theta_o_deg,phi_o_deg,bsdf,sigma\n0,0,10,0,x,1\n")
    with pytest.raises(CalibrationError, match=r"plain.csv: data row 1: column bsdf"):
        read_measured(path, ImportOptions(eta=1.5))


def test_reduced_netcdf_is_cf_and_reads_back(glass, tmp_path):
    data, _ = glass
    data = replace(data, shared_rel=np.full((len(data.bsdf), 1), 1e-3))
    path = write_reduced_netcdf(data, RECORD, tmp_path / "r.nc")
    checked = cf_counts(path)
    assert checked["said"] == [] and checked["counts"]["ERROR"] == 0
    with xarray.open_dataset(path) as ds:
        assert ds.attrs["Conventions"] == "CF-1.8" and "gonio" in ds.attrs["history"]
        np.testing.assert_array_equal(ds["bsdf"].values, data.bsdf)
        assert ds["bsdf"].attrs["units"] == "sr-1"
        assert ds["bsdf_expanded_uncertainty"].attrs["coverage_factor"] == 2.0
        np.testing.assert_array_equal(ds["u_beam"].values, data.components["beam"])
        assert float(ds["wavelength"]) == 632.8 and "theta_o" in ds.coords
        meanings = ds["side"].attrs["flag_meanings"].split()
        side = np.array(meanings)[ds["side"].values]
        np.testing.assert_array_equal(side == "transmission", data.transmission)
    back = read_reduced_netcdf(path)
    np.testing.assert_allclose(back.wo, data.wo, atol=1e-12)
    np.testing.assert_array_equal(back.bsdf, data.bsdf)
    np.testing.assert_array_equal(back.valid, data.valid)
    np.testing.assert_array_equal(back.flags, data.flags)
    assert back.meta["eta"] == 1.51 and back.meta["quantity"].startswith("BSDF")


def with_shared_errors(data):
    """The data with two shared errors (a 1 % one common to all points, a signed one on the
    transmission side), sigma holding them, and the budget naming them."""
    n = len(data.bsdf)
    shared = np.stack([np.full(n, 0.01), np.where(data.transmission, 0.02 * data.wo[:, 0], 0.0)],
                      axis=1)
    sigma = np.hypot(data.sigma, np.abs(data.bsdf) * np.linalg.norm(shared, axis=1))
    meta = dict(data.meta, budget={"own": ["read"], "shared": ["beam", "angle_offset"]})
    return replace(data, sigma=sigma, shared_rel=shared, meta=meta)


def test_reduced_netcdf_splits_u_into_random_and_shared_and_reads_the_covariance_back(
        glass, tmp_path):
    data = with_shared_errors(glass[0])
    path = write_reduced_netcdf(data, RECORD, tmp_path / "r.nc")
    assert cf_counts(path)["said"] == []
    with xarray.open_dataset(path) as ds:
        random, shared = ds["bsdf_random_uncertainty"].values, ds["bsdf_shared_uncertainty"].values
        corr = ds["bsdf_shared_error_correlation"].values
        assert ds["bsdf"].attrs["unc_comps"] == ["bsdf_random_uncertainty",
                                                 "bsdf_shared_uncertainty"]
        assert ds["bsdf_shared_uncertainty"].attrs["err_corr_1_form"] == "err_corr_matrix"
        assert ds["bsdf_standard_uncertainty"].attrs["coverage_probability"] == \
            pytest.approx(0.6827, abs=1e-4)
    np.testing.assert_allclose(np.hypot(random, shared), data.sigma, rtol=1e-12)
    errors = np.abs(data.bsdf)[:, None] * data.shared_rel
    np.testing.assert_allclose(corr * np.outer(shared, shared), errors @ errors.T, atol=1e-15)
    # read back as factors of the same shared covariance
    back = read_reduced_netcdf(path)
    got = np.abs(back.bsdf)[:, None] * back.shared_rel
    np.testing.assert_allclose(got @ got.T, errors @ errors.T, rtol=1e-9, atol=1e-18)
    plain = write_reduced_netcdf(glass[0], RECORD, tmp_path / "plain.nc")
    with xarray.open_dataset(plain) as ds:
        assert "bsdf_shared_error_correlation" not in ds.variables
        np.testing.assert_array_equal(ds["bsdf_random_uncertainty"].values, glass[0].sigma)
    assert read_reduced_netcdf(plain).shared_rel.shape == (len(glass[0].bsdf), 0)


def test_csv_and_astm_headers_state_the_shared_errors(glass, tmp_path):
    data = with_shared_errors(glass[0])
    request = ExportRequest()
    for fmt in ("csv", "astm"):
        paths, _ = write_data(data, fmt, "reduced", tmp_path / f"s.{fmt}", RECORD, request)
        for path in paths:
            header = [ln for ln in path.read_text().splitlines() if ln.startswith("#")]
            # the BRDF file's points share the common error only
            count = 1 if path.name == "s-BRDF.astm" else 2
            assert any(f"shared errors: {count}, from the components beam, angle_offset" in ln
                       for ln in header), path.name
            first = next(ln for ln in header if "shared error 1:" in ln)
            # the ASTM files: one per side, the BTDF first (s.astm, s-BRDF.astm)
            side = data.valid & (data.transmission == (path.name == "s.astm")) \
                if fmt == "astm" else np.ones(len(data.bsdf), bool)
            assert f"common to {int(side.sum())} of {int(side.sum())} points, relative size " \
                   "0.01" in first, path.name
    back = read_measured(tmp_path / "s.csv")
    assert set(back.components) == {"read", "beam"} and back.meta["budget"]["shared"] == [
        "beam", "angle_offset"]


def test_raw_netcdf_is_cf_with_an_epoch(tmp_path):
    r = np.zeros(4, READING_DTYPE)
    r["index"] = np.arange(4)
    r["kind"] = ["dark", "beam", "sample", "sample"]
    r["side"] = ["", "", "reflection", "transmission"]
    r["flags"] = ["", "retried", "retried,invalid", ""]
    r["t_s"] = [0.0, 0.5, 1.25, 2.0]
    r["power_w"] = [1e-9, 1e-3, 2e-6, 3e-6]
    r["saturated"] = [False, False, True, False]
    # t_s counts from meta.json's t0_epoch, taken before the devices open: seconds before the
    # record's started_utc (00:20:05.757 here); the times must decode from t0, not from it
    t0 = datetime(2026, 12, 2, 0, 20, 3, 250000, tzinfo=UTC).timestamp()
    path = write_raw_netcdf(r, RECORD, tmp_path / "raw.nc", t0_epoch=t0)
    checked = cf_counts(path)
    assert checked["said"] == [] and checked["counts"]["ERROR"] == 0
    with xarray.open_dataset(path) as ds:
        start = np.datetime64("2026-12-02T00:20:03.250")
        np.testing.assert_array_equal(ds["t_s"].values - start,
                                      (r["t_s"] * 1e9).astype("timedelta64[ns]"))
        meanings = np.array(ds["kind"].attrs["flag_meanings"].split())
        assert list(meanings[ds["kind"].values]) == list(r["kind"])
        masks = dict(zip(ds["flags"].attrs["flag_meanings"].split(),
                         ds["flags"].attrs["flag_masks"], strict=True))
        assert [bool(v & masks["retried"]) for v in ds["flags"].values] == [0, 1, 1, 0]
        assert ds["power_w"].attrs["units"] == "W"


def test_raw_netcdf_on_a_virtual_clock_is_run_time_not_an_epoch(tmp_path):
    # a run counted on the emulated bench's virtual clock: t_s is run time, so it must not
    # decode as dates after t0 (under --time-scale inf they would land in the future)
    r = np.zeros(3, READING_DTYPE)
    r["kind"], r["t_s"] = ["dark", "beam", "sample"], [0.0, 40.0, 3600.0]
    path = write_raw_netcdf(r, RECORD, tmp_path / "raw.nc", t0_epoch=1.7e9, virtual_clock=True)
    checked = cf_counts(path)
    assert checked["said"] == [] and checked["counts"]["ERROR"] == 0
    with xarray.open_dataset(path, decode_timedelta=False) as ds:
        np.testing.assert_array_equal(ds["t_s"].values, r["t_s"])
        assert ds["t_s"].attrs["units"] == "s" and "virtual clock" in ds["t_s"].attrs["comment"]
        assert "since" not in ds["t_s"].attrs["units"]


def libbsdf_parse(path: Path) -> tuple[list[str], int, list[list[float]]]:
    """What libbsdf's AstmReader::read takes from a file (its steps, in Python): header tokens
    skipped until `NUM_POINTS n` and `VARS a,b,...` (the rest of that line); then every
    non-empty line split at commas, angles below 0 shifted by 2 pi, values clamped at 0."""
    text = path.read_text()
    tokens = iter(text.split("\n"))
    names, num_points = [], -1
    for line in tokens:
        words = line.split()
        for k, word in enumerate(words):
            if word == "NUM_POINTS":
                num_points = int(words[k + 1])
            if word == "VARS":
                names = line.split(" ", 1)[1].split(",")
                break
        if names:
            break
    rows = []
    for line in tokens:
        if not line:
            continue
        values = [float(v) for v in line.split(",")]
        rows.append([v + 2 * math.pi if v < 0 else v for v in values[:4]]
                    + [max(v, 0.0) for v in values[4:]])
    return names, num_points, rows


def test_astm_layout_as_libbsdf_reads_it_and_round_trip(glass, tmp_path):
    data, _ = glass
    tables = astm_tables(data, ["record line VARS NUM_POINTS"])
    assert [t.data_type for t in tables] == ["BTDF", "BRDF"]
    for table in tables:
        path = write_astm(table, tmp_path / f"{table.data_type}.astm")
        names, num_points, rows = libbsdf_parse(path)
        assert names == ["theta_i", "phi_i", "theta_s", "phi_s", "632.8nm"]
        side = data.subset(data.valid & (data.transmission == (table.data_type == "BTDF")))
        assert num_points == len(rows) == len(side.bsdf)
        rows = np.array(rows)
        assert np.all((rows[:, [0, 2]] >= 0) & (rows[:, [0, 2]] <= math.pi / 2))
        assert np.all((rows[:, [1, 3]] >= 0) & (rows[:, [1, 3]] < 2 * math.pi))
        np.testing.assert_allclose(rows[:, 4], np.maximum(side.bsdf, 0.0), rtol=1e-8)
        np.testing.assert_allclose(np.cos(rows[:, 2]), np.abs(side.wo[:, 2]), atol=1e-9)
        back = read_measured(path, ImportOptions(eta=1.51, sigma_relative=0.02))
        np.testing.assert_allclose(back.wo, side.wo, atol=1e-9)
        np.testing.assert_allclose(back.wi, side.wi, atol=1e-9)
        np.testing.assert_allclose(back.bsdf, side.bsdf, rtol=1e-8)
        assert back.meta["wavelength_nm"] == 632.8
        assert np.all(back.transmission == (table.data_type == "BTDF"))


def test_zemax_measured_cells_comments_and_tis(glass, tmp_path):
    data, result = glass
    paths = measured_zemax_files(data, result, tmp_path / "m.bsdf", "synthetic")
    tables = [read_zemax(p) for p in paths]
    assert [t.scatter_type for t in tables] == ["BTDF", "BRDF"]
    model_tables = [read_zemax(p) for p in zemax_files(data, result, tmp_path / "f.bsdf")]
    for table, model_table in zip(tables, model_tables, strict=True):
        assert table.source == "Measured" and model_table.source == "Model"
        assert table.symmetry == "PlaneSymmetrical"
        side = data.subset(data.valid & (data.transmission == (table.scatter_type == "BTDF")))
        assert_measured_cells(table, side)
        blocks = [c for c in table.comments if c.startswith("block AngleOfIncidence")]
        assert len(blocks) == 2 and all("interpolated" in c and "ggx model" in c
                                        for c in blocks)
        for a in range(2):
            assert table_tis(table, 0, a) == pytest.approx(table.tis[0, a], rel=1e-5)
            # the data are the model plus 2 % noise: the TIS agrees with the model's
            assert table.tis[0, a] == pytest.approx(model_table.tis[0, a], rel=0.03)


def test_zemax_tis_uncertainty_matches_monte_carlo(glass):
    """The stated TIS u against the spread of the TIS over noise redrawn with the points'
    sigma (own and shared), 200 draws: within 15 % (the spread's own error is 5 %)."""
    data, result = glass
    side = data.subset(~data.transmission)
    side = replace(side, shared_rel=np.full((len(side.bsdf), 1), 0.01))
    side.sigma = np.hypot(side.sigma, 0.01 * side.bsdf)
    model = result.model()

    def tis(points) -> np.ndarray:
        table = measured_table(points, "BRDF", 1.51, model.eval, 20.0, True, [])
        return table.tis[0]

    stated = [float(c.split("+- ")[1].split()[0]) for c in measured_table(
        side, "BRDF", 1.51, model.eval, 20.0, True, []).comments]
    rng = np.random.default_rng(8)
    own = side.sigma_own
    draws = []
    for _ in range(200):
        shared = 1.0 + side.shared_rel @ rng.standard_normal(1)
        noisy = replace(side, bsdf=side.bsdf * shared + own * rng.standard_normal(len(own)))
        draws.append(tis(noisy))
    spread = np.std(draws, axis=0, ddof=1)
    np.testing.assert_allclose(spread, stated, rtol=0.15)


@pytest.mark.parametrize("fmt", ["csv", "netcdf", "astm", "zemax"])
def test_import_then_fit_recovers_alpha(fmt, glass, tmp_path):
    """Each measured format written by gonio, imported and fitted: alpha within 3 sigma of
    the truth (CSV and NetCDF carry sigma; ASTM and Zemax take an assumed 2 %, so within 2 %
    of it; the Zemax file's model fill is the fit it was written with, so the refit's
    alpha within 1 % of that fit's, which is within 3 sigma of the truth)."""
    data, result = glass
    request = ExportRequest(fit_options=FitOptions(distributions=("ggx",)))
    paths, _ = write_data(data, fmt, "reduced", tmp_path / f"glass.{fmt}", RECORD, request)
    back = read_measured(paths[-1], ImportOptions(eta=1.51, sigma_relative=0.02))
    refit = fit(back, FitOptions(distributions=("ggx",)))
    value, sigma = refit.param("alpha")
    if fmt in ("csv", "netcdf"):
        assert abs(value - ALPHA) < 3 * sigma
        assert value == pytest.approx(result.param("alpha")[0], rel=1e-9)
    elif fmt == "astm":
        assert value == pytest.approx(ALPHA, rel=0.02)
    else:
        assert value == pytest.approx(result.alpha, rel=0.01)
        assert abs(result.alpha - ALPHA) < 3 * result.param("alpha")[1]


def test_model_zemax_import_recovers_the_model(glass, tmp_path):
    """A model-only Zemax file, imported with its index and fitted: the tabulated fit's
    alpha again."""
    data, result = glass
    path = zemax_files(data.subset(~data.transmission), result, tmp_path / "m.bsdf")[0]
    assert read_zemax(path).source == "Model"
    back = read_measured(path, ImportOptions(sigma_relative=0.01, eta=1.51))
    refit = fit(back, FitOptions(distributions=("ggx",), fit_incidence_deg=None))
    assert refit.alpha == pytest.approx(result.alpha, rel=1e-4)


def test_model_export_takes_a_fit_json_and_refuses_a_bad_one(glass, tmp_path):
    data, result = glass
    fit_json = tmp_path / "fit.json"
    fit_json.write_text(json.dumps(result.to_dict()) + "\n")
    request = ExportRequest(fit_file=fit_json)
    xml, _ = write_data(data, "mitsuba", "model", tmp_path / "a.xml", RECORD, request)
    direct, _ = write_data(data, "mitsuba", "model", tmp_path / "b.xml", RECORD,
                           ExportRequest(fit_options=FitOptions(distributions=("ggx",))))
    assert xml[0].read_text() == direct[0].read_text()
    bad = dict(result.to_dict(), chi2_dof_fit=2.0e5)
    fit_json.write_text(json.dumps(bad))
    for fmt, what in (("mitsuba", "model"), ("zemax", "reduced"), ("astm", "model")):
        with pytest.raises(CalibrationError, match=r"chi2/dof is 2e\+05.*does not describe "
                                                   r"the data.*; give --fit a better fit.*--force"):
            write_data(data, fmt, what, tmp_path / f"c.{fmt}", RECORD, request)
    forced, notes = write_data(data, "mitsuba", "model", tmp_path / "d.xml", RECORD,
                               replace(request, force=True))
    assert notes[0].startswith("exported although the ggx fit's fitted chi2/dof")
    assert notes[0].endswith("(forced)") and notes[0] in forced[0].read_text()


def test_zemax_measured_asymmetrical_and_out_of_plane_incidence(glass, tmp_path):
    data, result = glass
    side = data.subset(data.valid & ~data.transmission)
    table = measured_table(side, "BRDF", 1.51, result.model().eval, 20.0, False, [])
    assert table.symmetry == "Asymmetrical" and {0.0, 180.0} <= set(table.azimuth_deg)
    assert table.azimuth_deg.max() == 360.0  # closing the circle: the row of azimuth 0 again
    np.testing.assert_array_equal(table.data[..., -1, :], table.data[..., 0, :])
    assert_measured_cells(table, side)
    # the sample turned by 30 deg about its normal: its own SampleRotation, the normal
    # incidence's points in both rotations
    both = ReducedData(*(np.concatenate([getattr(side, f), getattr(t, f)]) for f in (
        "wi", "wo", "bsdf", "sigma", "valid", "transmission")), dict(side.meta)) if (
        t := replace(side, wi=turned(side.wi, -30.0), wo=turned(side.wo, -30.0))) else None
    table = measured_table(both, "BRDF", 1.51, result.model().eval, 20.0, False, [])
    assert list(table.sample_rotation_deg) == [0.0, 30.0]
    at = measured_nodes(both, "BRDF", 1.51, False)
    assert len(at.point) == len(both.bsdf) + int(np.sum(both.theta_i_deg < 1e-9))
    cells = table.data[at.rotation, at.block, np.searchsorted(table.azimuth_deg, at.azimuth),
                       np.searchsorted(table.radial_deg, at.radial)]
    np.testing.assert_allclose(cells, np.maximum(both.bsdf[at.point], 0.0), rtol=1e-12)
    # imported again: each rotation's points where they were measured, in the sample frame
    path = write_zemax(table, tmp_path / "turned.bsdf")
    back = read_measured(path, ImportOptions(eta=1.51, sigma_relative=0.02))
    for j in np.flatnonzero(both.theta_i_deg > 1.0):
        distance = (np.linalg.norm(back.wi - both.wi[j], axis=1)
                    + np.linalg.norm(back.wo - both.wo[j], axis=1))
        nearest = int(np.argmin(distance))
        assert distance[nearest] < 1e-7, distance[nearest]  # its node: within 1e-6 deg of it
        same = ((np.linalg.norm(both.wi - both.wi[j], axis=1) < 1e-9)
                & (np.linalg.norm(both.wo - both.wo[j], axis=1) < 1e-9))  # repeats: the mean
        assert back.bsdf[nearest] == pytest.approx(max(np.mean(both.bsdf[same]), 0.0),
                                                   rel=1e-6)
    assert any(c.startswith("block SampleRotation 30 AngleOfIncidence 30 ")
               for c in table.comments)


def test_fit_and_reduce_import_cli(glass, tmp_path, capsys):
    data, result = glass
    path = write_reduced_csv(data, tmp_path / "glass.csv", record_lines(RECORD))
    assert main(["fit", "--import", str(path), "--json", "--distribution", "ggx"]) == 0
    out = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert out["run"] == str(path) and out["sample"]["id"] == "GG-7"
    assert out["parameters"]["alpha"]["value"] == pytest.approx(result.alpha, rel=1e-9)
    astm = write_astm(astm_tables(data)[1], tmp_path / "glass.astm")
    assert main(["reduce", "--import", str(astm), "--eta", "1.51", "--sigma-relative", "0.05",
                 "--out", str(tmp_path / "again.csv")]) == 0
    printed = capsys.readouterr().out.splitlines()
    assert printed[-1] == str(tmp_path / "again.csv")
    assert "assumed: u = 0.05 * |bsdf|" in printed[1]
    again = read_measured(tmp_path / "again.csv")
    assert again.meta["eta"] == 1.51 and "assumed" in again.meta["noise_model"]
    assert main(["fit", str(tmp_path), "--import", str(path)]) == 2
    assert "give a run directory or --import FILE (one of them)" in capsys.readouterr().err


def test_a_shared_error_line_leaves_out_float_noise_and_states_the_signs(glass):
    data = glass[0]
    n = len(data.bsdf)
    signed = np.where(np.arange(n) % 2 == 0, 8e-5, -4e-5)
    signed[:3] = [1.25e-17, -3e-18, 0.0]  # float noise of a sum that cancels
    data = replace(data, shared_rel=np.stack([np.full(n, 0.01), signed], axis=1),
                   meta=dict(data.meta, budget={"shared": ["beam", "angle_offset"]}))
    lines = shared_error_lines(data)
    assert lines[1] == (f"shared error 1: common to {n} of {n} points, relative size 0.01, "
                        "one sign at every point")
    positive = int(np.sum(signed > 1e-12))
    assert lines[2] == (f"shared error 2: common to {n - 3} of {n} points, relative size 4e-05 "
                        f"to 8e-05, positive at {positive} points and negative at "
                        f"{n - 3 - positive} (which ones: the NetCDF export's correlation)")
