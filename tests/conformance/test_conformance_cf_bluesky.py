"""Conformance: gonio's NetCDF and Bluesky exports read by readers gonio did not write. Every
NetCDF export (raw and reduced, of a run scanned on the emulated bench and of synthetic data
with shared errors) passes the CF checker (CF-1.8) and the IOOS compliance checker's CF 1.8
suite at its strict criteria with no error and no warning; obsarray reads the reduced file's
error structure as gonio's own covariance, and punpy, propagating what the file says alone,
gives the TIS uncertainty gonio's measured Zemax export states. Every Bluesky export validates
against event-model's schemas, and a Tiled server ingests it with its numeric columns numeric
and refuses a second ingest of the same run (HTTP 409)."""

from __future__ import annotations

import json
import math
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

TESTS = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(TESTS / "fitting"), str(TESTS / "bluesky"), str(TESTS)]

from cf_kit import cf_counts, compliance_findings  # noqa: E402
from required_tools import require_module  # noqa: E402

from calibration.exports.cf import read_reduced_netcdf, write_raw_netcdf, write_reduced_netcdf  # noqa: E402
from calibration.exports.cf_uncertainty import shared_errors  # noqa: E402
from calibration.exports.zemax_measured import measured_table  # noqa: E402
from calibration.synthetic import synthesize  # noqa: E402
from gonio.store import READING_DTYPE  # noqa: E402
from gonio_cli.main import main  # noqa: E402
from model.bsdf import RoughDielectric  # noqa: E402

pytestmark = pytest.mark.conformance
require_module("compliance_checker", "the strict CF checker (the test extra)")

ETA = 1.51
MODEL = RoughDielectric(distribution="ggx", alpha=0.394, eta=ETA)
RECORD = {"run": "synthetic", "wavelength_nm": 632.8}
NUMERIC = {"i", "f", "b"}  # numpy kinds of the readings' numeric fields


def shared_glass():
    """Synthetic ground glass (both sides, 0 and 30 deg) whose points share two errors: a 1 %
    beam error common to all, and a signed error on the transmission side (as a stage's zero
    offset gives through the model's slope); sigma holds them with the points' own 2 %."""
    data = synthesize("ggx", 0.394, incidences_deg=(0.0, 30.0), n_uniform=24, n_peak=12,
                      seed=5)
    data.meta["wavelength_nm"] = 632.8
    shared = np.stack([np.full(len(data.bsdf), 0.01),
                       np.where(data.transmission, 0.02 * data.wo[:, 0], 0.0)], axis=1)
    sigma = np.hypot(data.sigma, np.abs(data.bsdf) * np.linalg.norm(shared, axis=1))
    return replace(data, sigma=sigma, shared_rel=shared)


def raw_readings() -> np.ndarray:
    """Four readings of every kind, with flags and a saturated one."""
    r = np.zeros(4, READING_DTYPE)
    r["index"], r["point"] = np.arange(4), [0, 0, 1, 2]
    r["kind"] = ["dark", "beam", "sample", "sample"]
    r["side"] = ["", "", "reflection", "transmission"]
    r["flags"] = ["", "retried", "retried,invalid", ""]
    r["t_s"], r["power_w"] = [0.0, 0.5, 1.25, 2.0], [1e-9, 1e-3, 2e-6, 3e-6]
    r["saturated"] = [False, False, True, False]
    return r


@pytest.fixture(scope="module")
def scanned(tmp_path_factory):
    """A small plan scanned on the emulated bench: its run directory."""
    from bluesky_testkit import small_plan

    from gonio.runner import new_scan

    folder = tmp_path_factory.mktemp("conformance")
    result = new_scan(small_plan(folder), sim=True, out=folder / "runs", progress=False)
    assert result.outcome.status == "completed"
    return result.path


@pytest.fixture(scope="module")
def netcdf_exports(scanned, tmp_path_factory):
    """Every kind of NetCDF file gonio writes: the scanned run's raw and reduced exports (by
    `gonio export`; the small plan too small for the budget's angle terms), synthetic data with
    shared errors, raw readings on an epoch and on the
    emulated bench's virtual clock."""
    folder = tmp_path_factory.mktemp("netcdf")
    paths = []
    for what, options in (("raw", []), ("reduced", ["--no-angle-terms"])):
        out = folder / f"run-{what}.nc"
        assert main(["export", str(scanned), "--format", "netcdf", "--what", what,
                     "--out", str(out), *options]) == 0
        paths.append(out)
    paths.append(write_reduced_netcdf(shared_glass(), RECORD, folder / "shared.nc"))
    paths.append(write_raw_netcdf(raw_readings(), RECORD, folder / "epoch.nc", t0_epoch=1.7e9))
    paths.append(write_raw_netcdf(raw_readings(), RECORD, folder / "virtual.nc",
                                  t0_epoch=1.7e9, virtual_clock=True))
    return paths


def test_both_cf_checkers_pass_every_netcdf_export(netcdf_exports, tmp_path):
    for path in netcdf_exports:
        checked = cf_counts(path)
        assert checked["said"] == [], path.name
        assert checked["counts"]["ERROR"] == checked["counts"]["WARN"] == 0, path.name
        assert compliance_findings(path, tmp_path / f"{path.stem}.json") == [], path.name


def test_the_raw_integers_are_int32(netcdf_exports):
    import netCDF4

    with netCDF4.Dataset(netcdf_exports[0]) as ds:
        assert {ds[name].dtype for name in ("index", "point", "repeat")} == {np.dtype("i4")}
        assert ds["index"][:].tolist() == list(range(len(ds["index"])))


def test_obsarray_reads_gonios_covariance_and_punpy_propagates_the_stated_tis_u(tmp_path):
    """The file alone (values, uncertainties and error correlation as obsarray reads them)
    through punpy's law of propagation, with gonio's TIS of the measured Zemax table as the
    measurement function: the TIS standard uncertainty the Zemax export states (2 digits);
    without the file's correlation the same propagation is far off."""
    import obsarray  # noqa: F401 (registers the `unc` accessor)
    import xarray
    from punpy import LPUPropagation

    data = shared_glass()
    path = write_reduced_netcdf(data, RECORD, tmp_path / "shared.nc")
    with xarray.open_dataset(path) as ds:
        assert set(ds["bsdf"].attrs["uncertainty_variables"].split()) == {
            "bsdf_standard_uncertainty", "bsdf_expanded_uncertainty"}
        assert ds["bsdf_expanded_uncertainty"].attrs["coverage_probability"] == \
            pytest.approx(0.9545, abs=1e-4)
        unc = ds.unc["bsdf"]
        cov = unc.total_err_cov_matrix().values
        u = unc.total_unc().values
        corr = unc.total_err_corr_matrix().values
        values = ds["bsdf"].values
    errors = shared_errors(data)
    gonio_cov = np.diag(data.sigma_own**2) + errors @ errors.T
    np.testing.assert_allclose(cov, gonio_cov, rtol=1e-12, atol=1e-12 * gonio_cov.max())
    np.testing.assert_allclose(u, data.sigma, rtol=1e-12)

    back = read_reduced_netcdf(path)
    keep = back.valid & ~back.transmission
    points = back.subset(keep)

    def tis(bsdf: np.ndarray) -> np.ndarray:
        return measured_table(replace(points, bsdf=bsdf), "BRDF", ETA, MODEL.eval, 20.0, True,
                              []).tis[0]

    side = data.subset(data.valid & ~data.transmission)
    comments = measured_table(side, "BRDF", ETA, MODEL.eval, 20.0, True, []).comments
    stated = np.array([float(c.split("+- ")[1].split()[0]) for c in comments if "+- " in c])
    assert len(stated) == 2
    lpu = LPUPropagation()
    got = lpu.propagate_standard(tis, [values[keep]], [u[keep]], [corr[np.ix_(keep, keep)]])
    digit = 10.0 ** (np.floor(np.log10(stated)) - 1)  # the stated u's second digit
    assert np.all(np.abs(got - stated) <= 0.5 * digit * (1 + 1e-9)), (got, stated)
    alone = lpu.propagate_standard(tis, [values[keep]], [u[keep]], ["rand"])
    assert np.all(alone < 0.6 * stated), (alone, stated)


def bluesky_documents(run_dir: Path, out: Path) -> list[tuple[str, dict]]:
    """`gonio export RUN --format bluesky`'s documents, as Python's json reads them."""
    assert main(["export", str(run_dir), "--format", "bluesky", "--out", str(out)]) == 0
    return [tuple(json.loads(line)) for line in out.read_text().splitlines()]


def test_event_model_validates_every_bluesky_export_with_nan_as_numbers(scanned, tmp_path):
    from bluesky_testkit import validated

    docs = validated(bluesky_documents(scanned, tmp_path / "run.jsonl"))
    events = [doc["data"] for name, doc in docs if name == "event"]
    darks = [e for e in events if e["kind"] == "dark"]
    assert darks and all(math.isnan(e["plan_theta_i_deg"]) for e in darks)
    numeric = [n for n in READING_DTYPE.names if READING_DTYPE[n].kind in NUMERIC]
    assert all(isinstance(e[n], (int, float)) for e in events for n in numeric)


def test_tiled_ingests_the_documents_with_numeric_columns_and_refuses_a_second_ingest(
        scanned, tmp_path):
    """Tiled's own writer (bluesky's TiledWriter) ingests the export event by event into a
    Tiled server on 127.0.0.1: every numeric reading field reads back numeric (a dark
    reading's NaN plan angles, written as null, made them strings); the same run ingested
    again is refused with HTTP 409, as its uids are the run's own."""
    require_module("tiled.server", "a Tiled server (tiled[server])")
    from bluesky.callbacks.tiled_writer import TiledWriter
    from tiled.client import from_uri
    from tiled.client.utils import ClientError
    from tiled.server import SimpleTiledServer

    docs = bluesky_documents(scanned, tmp_path / "run.jsonl")
    with SimpleTiledServer(directory=tmp_path / "tiled") as server:
        client = from_uri(server.uri)
        writer = TiledWriter(client, batch_size=1)
        for name, doc in docs:
            writer(name, doc)
        stream = client[docs[0][1]["uid"]]["primary"].read()
        for name in READING_DTYPE.names:
            kind = READING_DTYPE[name].kind
            assert (stream[name].dtype.kind in NUMERIC) == (kind in NUMERIC), name
        assert np.isnan(stream["plan_theta_i_deg"].values[stream["kind"].values == "dark"]).all()
        again = TiledWriter(client)
        with pytest.raises(ClientError, match="409"):
            for name, doc in docs:
                again(name, doc)
