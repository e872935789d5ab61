"""Conformance with libbsdf, a reader nobody here wrote: every ASTM E1392 and Zemax tabular
BSDF export (reduced data and fitted model) of Walter's ground glass measured on the emulated
bench (0 and 30 deg, both sides, its multiple-scattering fit) is read by libbsdf's own
readers, and at every measured point libbsdf returns gonio's value within 1e-4 relative, or,
for a Zemax file, within libbsdf's float32 precision (libbsdf_float: half a float32 ulp of the
largest value it blends there), whichever is larger.

Frames: libbsdf reads an isotropic ASTM file into its own frame, the source on +x (gonio's
sample frame has it on -x: a half turn about the normal). Its Zemax frame is gonio's sample
frame mirrored in x (the source of SampleRotation p at azimuth p, ScatterAzimuth 90 toward +y),
and it takes a BTDF block's AngleOfIncidence (the refracted direction's angle) as the
incidence angle."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from fitting.fitting_bench_runs import instrument, plan, scan
from libbsdf_float import blend_bounds, point_bounds
from libbsdf_reader import ReaderUnavailable, ToolMissing, build_probe, libbsdf_values
from required_tools import tool_missing

from calibration.exports.astm import directions, read_astm
from calibration.exports.model import zemax_files
from calibration.exports.zemax import read_zemax, turned, write_zemax
from calibration.exports.zemax_measured import measured_nodes, measured_table
from calibration.fit import FitOptions, FitResult, fit
from calibration.pipeline import reduce_run
from calibration.reduced import ReducedData
from calibration.synthetic import synthesize
from gonio_cli.main import main
from model.bsdf.families import make_family

pytestmark = pytest.mark.conformance

RELATIVE = 1e-4  # the agreement asked of a reader at a measured point
HALF_TURN = np.array([-1.0, -1.0, 1.0])  # gonio's sample frame -> libbsdf's (ASTM)
MIRROR = np.array([-1.0, 1.0, 1.0])  # gonio's sample frame -> libbsdf's (Zemax)
SOURCE = {"power_w": 1e-3, "beam_diameter_mm": 2.0, "divergence_deg": 0.03}
APERTURE = {"diameter_mm": 10.0, "distance_mm": 500.0, "rtol": 1e-5}
GRIDS = [
    {"side": "transmission", "theta_i_deg": 0.0,
     "theta_o_deg": {"start": -70.0, "stop": 70.0, "step": 3.5}},
    {"side": "reflection", "theta_i_deg": 0.0,
     "theta_o_deg": {"start": 8.0, "stop": 80.0, "step": 6.0}},
    {"side": "transmission", "theta_i_deg": 30.0,
     "theta_o_deg": {"start": -63.0, "stop": 63.0, "step": 7.0}},
    {"side": "reflection", "theta_i_deg": 30.0,
     "theta_o_deg": {"start": -80.0, "stop": 80.0, "step": 8.0}, "skip_forbidden": True},
]


@pytest.fixture(scope="module")
def probe() -> Path:
    """libbsdf's probe: a missing tool skips or fails (required_tools), a missing snapshot
    skips."""
    try:
        return build_probe()
    except ToolMissing as why:
        tool_missing(f"libbsdf cannot be built: {why}")
    except ReaderUnavailable as why:
        pytest.skip(f"libbsdf not available: {why}")


@pytest.fixture(scope="module")
def ground_glass(tmp_path_factory) -> tuple[Path, Path]:
    """(run, fit JSON) of Walter's ground glass (GGX alpha 0.394) on the emulated bench, which
    adds multiple scattering, and its multiple-scattering fit."""
    tmp = tmp_path_factory.mktemp("ground-glass")
    cfg = instrument(tmp, {"source": SOURCE, "aperture": APERTURE, "sample": {
        "kind": "hemisphere", "distribution": "ggx", "alpha": 0.394, "eta": 1.51,
        "ms_walks": 1 << 21}}, seed=2)
    run = scan(plan(tmp, "ground-glass", GRIDS), cfg, tmp / "runs")
    fit_json = tmp / "fit.json"
    with pytest.MonkeyPatch.context() as patch:
        lines: list[str] = []
        patch.setattr("builtins.print", lambda *a, **k: lines.append(" ".join(map(str, a))))
        assert main(["fit", str(run), "--json", "--distribution", "ggx",
                     "--multiple-scattering"]) == 0
    fit_json.write_text(lines[-1] + "\n")
    return run, fit_json


def export(run: Path, fit_json: Path, fmt: str, what: str, out: Path) -> list[Path]:
    """The files `gonio export` writes (both sides: the BTDF at `out`, the BRDF beside it)."""
    assert main(["export", str(run), "--format", fmt, "--what", what, "--fit", str(fit_json),
                 "--out", str(out)]) == 0
    files = [out, out.with_name(f"{out.stem}-BRDF{out.suffix}")]
    assert all(f.is_file() for f in files)
    return files


def side(data: ReducedData, scatter_type: str) -> ReducedData:
    """The valid points of one side."""
    return data.subset(data.valid & (data.transmission == (scatter_type == "BTDF")))


def libbsdf_frame(wi: np.ndarray, wo: np.ndarray, frame: np.ndarray = HALF_TURN
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Directions of gonio's sample frame in libbsdf's (no -0 left, which libbsdf's atan2
    would take for an azimuth of pi at normal incidence)."""
    return wi * frame + 0.0, wo * frame + 0.0


def zemax_directions(path: Path, points: ReducedData) -> tuple[np.ndarray, np.ndarray]:
    """(wi, wo) of the points as libbsdf reads a Zemax file: in its frame, and for a BTDF the
    incidence at the block's AngleOfIncidence, from the source's azimuth."""
    wi, wo = libbsdf_frame(points.wi, points.wo, MIRROR)
    if read_zemax(path).scatter_type == "BTDF":
        angle = np.arcsin(np.sin(np.radians(points.theta_i_deg)) / points.meta["eta"])
        azimuth = np.arctan2(wi[:, 1], wi[:, 0])
        wi = np.stack([np.sin(angle) * np.cos(azimuth), np.sin(angle) * np.sin(azimuth),
                       np.cos(angle)], axis=1) + 0.0
    return wi, wo


def disagreement(expected: np.ndarray, got: np.ndarray) -> np.ndarray:
    """Relative disagreements (absolute where gonio's value is 0: a negative measured value,
    which the files write as 0)."""
    return np.abs(got - expected) / np.where(expected != 0, np.abs(expected), 1.0)


def worst(expected: np.ndarray, got: np.ndarray) -> float:
    """The largest relative disagreement."""
    return float(np.max(disagreement(expected, got)))


def assert_within_float32(expected: np.ndarray, got: np.ndarray, bound: np.ndarray,
                          what: str) -> None:
    """Every value within RELATIVE (disagreement) or, where that is the larger, within libbsdf's
    float32 bound (libbsdf_float); prints how many points needed that bound and its largest."""
    scale = np.where(expected != 0, np.abs(expected), 1.0)
    allowed = np.maximum(RELATIVE * scale, bound)
    off = np.abs(got - expected)
    assert np.all(off <= allowed), (what, off[off > allowed], allowed[off > allowed])
    needed = off > RELATIVE * scale
    largest = float(bound[needed].max(initial=0.0))
    elsewhere = float(np.max(off[~needed] / scale[~needed], initial=0.0))
    print(f"{what}: {needed.sum()} of {len(off)} points within libbsdf's float32 bound only "
          f"(largest bound {largest:.2g}, relative {float(np.max(off / scale)):.2g}); "
          f"elsewhere worst {elsewhere:.2g} relative")


def test_astm_reduced_read_by_libbsdf(probe, ground_glass, tmp_path):
    """Every measured value of both ASTM files comes back from libbsdf."""
    run, fit_json = ground_glass
    data = reduce_run(run)
    for path in export(run, fit_json, "astm", "reduced", tmp_path / "glass.astm"):
        table = read_astm(path)
        points = side(data, table.data_type)
        kind, got = libbsdf_values(probe, f"astm-{table.data_type.lower()}", path,
                                   *libbsdf_frame(points.wi, points.wo))
        assert kind == table.data_type
        assert worst(np.maximum(points.bsdf, 0.0), got) < RELATIVE, path.name


def test_astm_model_read_by_libbsdf(probe, ground_glass, tmp_path):
    """The model's ASTM grid: libbsdf returns the tabulated value at each of its nodes."""
    run, fit_json = ground_glass
    for path in export(run, fit_json, "astm", "model", tmp_path / "model.astm"):
        table = read_astm(path)
        wi, wo, _ = directions(table)
        _, got = libbsdf_values(probe, f"astm-{table.data_type.lower()}", path,
                                *libbsdf_frame(wi, wo))
        keep = table.values[:, 0] > 0
        assert worst(table.values[keep, 0], got[keep]) < RELATIVE, path.name


def test_zemax_reduced_read_by_libbsdf(probe, ground_glass, tmp_path):
    """The measured Zemax tables: libbsdf returns every measured value where it was
    measured."""
    run, fit_json = ground_glass
    data = reduce_run(run)
    for path in export(run, fit_json, "zemax", "reduced", tmp_path / "glass.bsdf"):
        table = read_zemax(path)
        points = side(data, table.scatter_type)
        wi, wo = zemax_directions(path, points)
        kind, got = libbsdf_values(probe, "zemax", path, wi, wo)
        assert kind == table.scatter_type
        nodes = measured_nodes(points, table.scatter_type, points.meta["eta"],
                               table.symmetry == "PlaneSymmetrical")
        assert_within_float32(np.maximum(points.bsdf, 0.0), got,
                              point_bounds(table, nodes, len(points.bsdf)), path.name)


def test_zemax_model_read_by_libbsdf(probe, ground_glass, tmp_path):
    """The model's Zemax tables hold every measured direction as a node: there libbsdf returns
    the value gonio tabulated."""
    run, fit_json = ground_glass
    data = reduce_run(run)
    for path in export(run, fit_json, "zemax", "model", tmp_path / "model.bsdf"):
        table = read_zemax(path)
        assert_nodes_read_back(probe, path, side(data, table.scatter_type),
                               data.meta["eta"])


def assert_nodes_read_back(probe, path: Path, points: ReducedData, eta: float) -> np.ndarray:
    """libbsdf's values of a model table at the measured directions, its nodes (the table's
    index `eta`), against the table's own values there (assert_within_float32); returns the
    table's values."""
    table = read_zemax(path)
    at = measured_nodes(points, table.scatter_type, eta, True)
    blocks = [int(np.flatnonzero(np.isclose(table.angle_deg, a))[0]) for a in at.angle_deg]
    expected = table.data[0, np.array(blocks)[at.block],
                          np.searchsorted(table.azimuth_deg, at.azimuth),
                          np.searchsorted(table.radial_deg, at.radial)]
    _, got = libbsdf_values(probe, "zemax", path,
                            *zemax_directions(path, points.subset(at.point)))
    assert_within_float32(expected, got, blend_bounds(table, at), path.name)
    return expected


@pytest.mark.parametrize("family, values, settings", [
    ("lambert", {"rho": 0.62}, {}), ("oren-nayar", {"rho": 0.7, "sigma": 0.35}, {}),
    ("lambert+microfacet", {"rho": 0.5, "alpha": 0.2, "eta": 1.5}, {"distribution": "ggx"}),
    ("abg", {"A": 2e-3, "B": 1e-4, "g": 1.8}, {})])
def test_zemax_family_tables_read_by_libbsdf(probe, tmp_path, family, values, settings):
    """A model family's Zemax table (the general export of every family): libbsdf returns the
    family's value at every measured direction, its nodes."""
    data = synthesize("ggx", 0.3, incidences_deg=(0.0, 30.0, 60.0), sides=("reflection",))
    result = FitResult(distribution=settings.get("distribution", ""), masking="separable",
                       names=tuple(values), values=np.array(list(values.values())),
                       errors=np.zeros(len(values)), covariance=np.eye(len(values)), eta=1.0,
                       k=None, chi2_dof_fit=1.0, n_fit=len(data.bsdf), chi2_dof_heldout=None,
                       n_heldout=0, preferred_by=None, family=family)
    (path,) = zemax_files(data, result, tmp_path / f"{family}.bsdf", "test")
    points = data.subset(data.valid)
    at = measured_nodes(points, "BRDF", 1.0, True)
    expected = assert_nodes_read_back(probe, path, points, 1.0)
    model = make_family(family, values, **settings)
    # the nodes are the measured directions to the grid's rounding (1e-6 deg)
    np.testing.assert_allclose(expected, model.eval(points.wi[at.point], points.wo[at.point]),
                               rtol=1e-5)


@pytest.mark.parametrize("scatter_type", ["BRDF", "BTDF"])
def test_zemax_sample_rotations_read_by_libbsdf(scatter_type, probe, tmp_path):
    """A run with sample azimuths (0, 45 and 120 deg; gonio's sample frame turned by -p) is one
    SampleRotation per azimuth, each block holding its points; libbsdf returns every measured
    value within 1e-4 relative or within its float32 precision: on the BTDF's lobe edge a value
    4e-8 of the peak lies beside a block whose value at the same cell is 2e4 times larger, and
    libbsdf's blend from that block returns it within half a float32 ulp of that value."""
    data = synthesize("ggx", 0.394, incidences_deg=(0.0, 30.0), n_uniform=24, n_peak=12,
                      seed=5)
    turns = [data.subset(data.valid)]
    for p in (45.0, 120.0):
        turns.append(replace(turns[0], wi=turned(turns[0].wi, -p), wo=turned(turns[0].wo, -p)))
    rotated = ReducedData(*(np.concatenate([getattr(t, f) for t in turns]) for f in (
        "wi", "wo", "bsdf", "sigma", "valid", "transmission")), dict(turns[0].meta))
    model = fit(data, FitOptions(distributions=("ggx",))).model()
    table = measured_table(rotated, scatter_type, 1.51, model.eval, 20.0, False, [])
    assert list(table.sample_rotation_deg) == [0.0, 45.0, 120.0]
    path = write_zemax(table, tmp_path / "turned.bsdf")
    points = side(rotated, scatter_type)
    kind, got = libbsdf_values(probe, "zemax", path, *zemax_directions(path, points))
    assert kind == scatter_type
    nodes = measured_nodes(points, scatter_type, 1.51, False)
    assert_within_float32(np.maximum(points.bsdf, 0.0), got,
                          point_bounds(read_zemax(path), nodes, len(points.bsdf)), scatter_type)


def test_astm_isotropic_near_normal_incidence(probe, ground_glass, tmp_path):
    """libbsdf reads the ASTM file as isotropic: just off normal incidence on the source side
    it returns the normal-incidence values (a file naming two incidence azimuths is read as
    anisotropic, its gaps filled with the nearest sample)."""
    run, fit_json = ground_glass
    data = reduce_run(run)
    path = export(run, fit_json, "astm", "reduced", tmp_path / "glass.astm")[0]
    points = side(data, "BTDF")
    normal = points.subset(points.theta_i_deg < 1e-9)
    tilt = math.radians(1e-6)
    wi = np.tile([-math.sin(tilt), 0.0, math.cos(tilt)], (len(normal.bsdf), 1))
    _, got = libbsdf_values(probe, "astm-btdf", path, *libbsdf_frame(wi, normal.wo))
    assert worst(normal.bsdf, got) < RELATIVE
