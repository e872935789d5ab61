"""The LUT machinery (axes, tiling, Dask layouts, storage, interpolation, validation) checked
with an analytic stand-in integrand whose exact integral is known."""

from __future__ import annotations

import importlib
import json
import math

import numpy as np
import pytest

from model.cluster import map_tasks, run_with_one_kernel_thread, threads_per_worker, usable_cores
from model.lut import TableSpec, bake, load_table, parse_size, validate
from model.lut.axes import ETA_MAX, axes_for
from model.lut.bake import grid_points, integrate_tile
from model.lut.remap import albedo_factor
from model.lut.table import Table, interpolate
from model.lut.validate import TIR_BAND, edge_split, near_critical, random_points, stored_values


class StandIn:
    """Monte Carlo of exp(-alpha u0) (1 + mu u1) eta^u2 over the unit cube (one channel per
    table channel, the second scaled by 1/2), with a zero-mean rng jitter so stochastic
    estimators are exercised too."""

    def __init__(self, channels=("transmittance",)):
        self.channels = channels
        self.description = "stand-in"

    def __call__(self, params, u, rng):
        mu, alpha = params[:, :1], params[:, 1:2]
        eta = params[:, 2:3] if params.shape[1] > 2 else np.full_like(mu, 2.0)
        g = np.exp(-alpha * u[:, 0]) * (1 + mu * u[:, 1]) * eta ** u[:, 2]
        g = g * (1.0 + 1e-3 * (rng.random(len(u)) - 0.5))
        value = g.mean(axis=1)
        return np.stack([value * (k + 1) / (k + 1) ** 2 for k in range(len(self.channels))], -1)

    @staticmethod
    def exact(mu, alpha, eta=2.0):
        a = np.where(alpha > 0, alpha, 1.0)
        first = np.where(alpha > 0, -np.expm1(-a) / a, 1.0)
        return first * (1 + mu / 2) * (eta - 1) / np.log(eta)


SPEC = TableSpec(kind="transmission", shape=(6, 5, 4), dtype="float32", samples=256, seed=7,
                 tile_entries=16)


@pytest.fixture(scope="module")
def client():
    """One in-process 2-worker distributed cluster for the whole module."""
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False,
                                  dashboard_address=":0") as cluster:
        with distributed.Client(cluster) as c:
            yield c


def test_parse_size_and_spec_errors_name_the_field():
    assert parse_size("64x64x32") == (64, 64, 32)
    for bad, word in [("64by64", "size"), ("64x1", "at least 2")]:
        with pytest.raises(ValueError, match=word):
            parse_size(bad)
    with pytest.raises(ValueError, match="3 axes"):
        TableSpec(kind="transmission", shape=(8, 8))
    with pytest.raises(ValueError, match="2 axes"):
        TableSpec(kind="reflection", shape=(8, 8, 8))
    with pytest.raises(ValueError, match="dtype"):
        TableSpec(dtype="int8")
    with pytest.raises(ValueError, match="power of two"):
        TableSpec(samples=1000)
    with pytest.raises(ValueError, match="multiple scattering"):
        TableSpec(kind="reflection", shape=(8, 8), multiple_scattering=True)


def test_axes_are_texel_centres_and_invert():
    mu, alpha, eta = axes_for("transmission", (8, 16, 32))
    assert np.allclose(mu.coords(), (np.arange(8) + 0.5) / 8)
    assert np.allclose(alpha.values(), ((np.arange(16) + 0.5) / 16) ** 2)
    # eta axis is symmetric in log: entering and leaving get the same resolution
    assert np.allclose(eta.values() * eta.values()[::-1], 1.0)
    assert eta.to_value(0.0) == pytest.approx(1 / ETA_MAX) and eta.to_value(1.0) == ETA_MAX
    t = np.linspace(0, 1, 101)
    for axis in (mu, alpha, eta):
        assert np.allclose(axis.to_coord(axis.to_value(t)), t)


def test_interpolation_is_exact_for_multilinear_data_and_clamps_to_edge():
    rng = np.random.default_rng(3)
    shape = (5, 4, 3)
    coeff = rng.normal(size=4)
    centres = [(np.arange(n) + 0.5) / n for n in shape]
    grid = np.meshgrid(*centres, indexing="ij")
    data = (coeff[0] + coeff[1] * grid[0] + coeff[2] * grid[1] * grid[2]
            + coeff[3] * grid[0] * grid[1] * grid[2])[..., None]
    t = [rng.uniform(0.5 / n, 1 - 0.5 / n, 200) for n in shape]
    expected = coeff[0] + coeff[1] * t[0] + coeff[2] * t[1] * t[2] + coeff[3] * t[0] * t[1] * t[2]
    assert np.allclose(interpolate(data, t)[..., 0], expected, rtol=0, atol=1e-12)
    # beyond the outer texel centres the value is the edge texel's (clamp to edge)
    edge = interpolate(data, [np.array([0.0, 1.0]), np.array([0.0, 1.0]), np.array([0.0, 1.0])])
    assert edge[0, 0] == pytest.approx(data[0, 0, 0, 0]) and edge[1, 0] == data[-1, -1, -1, 0]


def test_bake_converges_to_the_exact_integral():
    table = bake(SPEC, StandIn())
    exact = StandIn.exact(*grid_points(SPEC).T)
    err = np.abs(stored_values(table)[:, 0] - exact)
    assert err.max() < 2e-3  # Sobol, 256 points, plus the 1e-3/sqrt(12)/16 jitter
    assert table.data.dtype == np.float32 and np.isfinite(table.data).all()


def test_same_bits_whatever_the_layout(client, monkeypatch):
    """Serial loop over tiles, threaded Dask, a 2-worker distributed cluster and any number of
    tiles per Dask task agree bitwise."""
    estimator = StandIn()
    threads = bake(SPEC, estimator).data
    cluster = bake(SPEC, estimator, client=client).data
    points = grid_points(SPEC)
    serial = np.concatenate([
        integrate_tile(points[s:s + SPEC.tile_entries], estimator, SPEC.samples, SPEC.seed, k)
        for k, s in enumerate(range(0, len(points), SPEC.tile_entries))
    ]) * albedo_factor(SPEC.remapped, points[:, 2:3])  # a remapped table stores eta^2 T
    serial = serial.reshape(threads.shape).astype(SPEC.dtype)
    assert threads.tobytes() == cluster.tobytes() == serial.tobytes()
    for per_thread in (1, 1000):  # one task per thread, one tile per task
        # the module by name: the attribute model.lut.bake is the bake function
        monkeypatch.setattr(importlib.import_module("model.lut.bake"), "TASKS_PER_THREAD",
                            per_thread)
        assert bake(SPEC, estimator).data.tobytes() == threads.tobytes()
    other_seed = bake(TableSpec(**{**SPEC.to_dict(), "shape": SPEC.shape, "seed": 8}), estimator)
    assert other_seed.data.tobytes() != threads.tobytes()


def test_npz_round_trip_keeps_bits_axes_and_metadata(tmp_path):
    spec = TableSpec(kind="reflection", shape=(4, 3), dtype="float16", samples=64,
                     tile_entries=5)
    table = bake(spec, StandIn(("scale", "bias")))
    path = table.save(tmp_path / "r.npz")
    loaded = load_table(path)
    assert loaded.data.tobytes() == table.data.tobytes() and loaded.data.dtype == np.float16
    assert loaded.spec == spec and loaded.model == "stand-in"
    with np.load(path, allow_pickle=False) as f:
        meta = json.loads(str(f["metadata"]))
        assert np.allclose(f["axis_alpha"], ((np.arange(3) + 0.5) / 3) ** 2)
        assert set(f.files) == {"table", "metadata", "axis_cos_theta", "axis_alpha"}
    assert meta["channels"] == ["scale", "bias"]
    assert meta["index_order"] == ["alpha", "cos_theta", "channel"]
    assert loaded.data.shape == (3, 4, 2)  # N.V runs fastest: texture x
    assert "sqrt(alpha)" in meta["axes"][1]["parameterisation"]
    bad = tmp_path / "bad.npz"
    np.savez(bad, x=np.zeros(3))
    with pytest.raises(ValueError, match="not a gonio lookup table"):
        load_table(bad)


def test_validation_separates_interpolation_error_from_noise(client):
    # remap none: the stand-in is smooth in N.V itself (the remap follows the model's edges)
    spec = TableSpec(kind="transmission", shape=(4, 4, 4), dtype="float64", samples=128,
                     tile_entries=32, remap="none")
    estimator = StandIn()
    table = bake(spec, estimator)
    report = validate(table, estimator, points=300, reference_samples=1024, client=client)
    assert report.entries_checked == 64 and report.points_checked == 300
    assert report.entry_max < 5e-3  # the table's own Monte Carlo error
    assert report.reference_noise_rms < report.entry_rms + 1e-9
    # a coarse 4^3 grid of a curved function: lookups are worse than entries
    assert report.lookup_max > 3 * report.entry_max
    # and the lookup error matches an exact check of the same table
    params = random_points(spec, 2000, seed=0).T
    direct = np.abs(table.lookup(*params)[..., 0] - StandIn.exact(*params))
    assert report.lookup_rms == pytest.approx(np.sqrt(np.mean(direct**2)), rel=0.3)
    finer = bake(TableSpec(**{**spec.to_dict(), "shape": (16, 16, 16)}), estimator)
    fine_report = validate(finer, estimator, entries=50, points=300, reference_samples=1024)
    assert fine_report.entries_checked == 50
    assert fine_report.lookup_rms < report.lookup_rms / 4


def test_lookup_rejects_the_wrong_number_of_parameters():
    table = Table(spec=SPEC, data=np.zeros(SPEC.array_shape, np.float32))
    with pytest.raises(ValueError, match="takes 3 parameters"):
        table.lookup(0.5, 0.1)
    assert math.isfinite(table.lookup(0.5, 0.1, 1.5)[0])


def test_a_non_finite_estimate_is_named():
    class Broken(StandIn):
        def __call__(self, params, u, rng):
            out = super().__call__(params, u, rng)
            out[params[:, 1] > 0.5] = np.nan
            return out

    spec = TableSpec(kind="transmission", shape=(2, 2, 2), samples=4)
    with pytest.raises(ValueError, match=r"non-finite table value at \(N.V, alpha\[, eta\]\)"):
        bake(spec, Broken())


def test_tasks_run_kernels_on_one_thread_and_workers_share_the_cores(client):
    """The thread policy of model.cluster: inside a task numba runs one thread (restored
    after), in-process and on a cluster; local workers x threads never exceed the cores."""
    numba = pytest.importorskip("numba")
    before = numba.get_num_threads()
    assert map_tasks(numba.get_num_threads, [()] * 4) == [1] * 4
    assert map_tasks(numba.get_num_threads, [()] * 4, client) == [1] * 4
    assert run_with_one_kernel_thread(numba.get_num_threads) == 1
    assert numba.get_num_threads() == before
    cores = usable_cores()
    for workers in (1, 2, 3, cores, 2 * cores):
        threads = threads_per_worker(workers)
        assert threads >= 1 and (workers * threads <= cores or threads == 1)
    assert threads_per_worker(1) == cores


def test_lookup_errors_are_split_at_the_tir_edge_band():
    """near_critical marks eta < 1 points within TIR_BAND of N.V_c = sqrt(1 - eta^2) only;
    the report's edge and rest parts recombine to the whole."""
    eta = 1 / 1.5
    critical = np.sqrt(1 - eta**2)
    params = np.array([[critical, 0.1, eta], [critical + 0.9 * TIR_BAND, 0.1, eta],
                       [critical - 1.1 * TIR_BAND, 0.1, eta], [critical, 0.1, 1.5],
                       [0.0, 0.1, 1.0]])
    assert near_critical(params).tolist() == [True, True, False, False, False]
    spec = TableSpec(kind="transmission", shape=(4, 4, 4), dtype="float64", samples=64,
                     tile_entries=32)
    report = validate(bake(spec, StandIn()), StandIn(), points=400, reference_samples=256)
    d = report.to_dict()
    assert 0 < d["edge_points"] < 400 and d["tir_band"] == TIR_BAND
    assert d["unity_eta"] == pytest.approx(tuple(spec.axes[2].values()[1:3]))  # 4 nodes
    assert d["unity_eta"][0] < 1 < d["unity_eta"][1]
    assert 0 < d["unity_points"] < 400
    assert report.lookup_max == max(d[f"{p}_lookup_max"] for p in ("edge", "unity", "rest"))
    # the parts of edge_split: TIR band, between the nodes bracketing eta = 1, neither
    err = np.array([1.0, 2.0, 3.0, 4.0, 5.0])
    split = edge_split(params, err, (0.9, 1.1))
    assert (split["edge_points"], split["unity_points"]) == (2, 1)
    assert (split["edge_lookup_max"], split["unity_lookup_max"]) == (2.0, 5.0)
    assert split["rest_lookup_rms"] == pytest.approx(np.sqrt((9 + 16) / 2))
    reflection = TableSpec(kind="reflection", shape=(4, 4), samples=64)
    r = validate(bake(reflection, StandIn(("scale", "bias"))), StandIn(("scale", "bias")),
                 points=50, reference_samples=256)
    assert r.edge_points is None and r.rest_lookup_rms is None
