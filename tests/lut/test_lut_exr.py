"""OpenEXR tables: HALF / FLOAT channels, the eta-slice atlas read back pixel by pixel with the
OpenEXR bindings themselves, metadata in header attributes, exact round trips, CLI and errors."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

from gonio_cli.main import main
from model.lut import TableSpec, bake, load_table
from model.lut.bake import grid_points
from model.lut.remap import albedo_factor
from model.lut.table import Table, interpolate, texture_coords
from model.lut.validate import random_points

if os.environ.get("CI"):
    import OpenEXR  # CI installs the test extra, which includes gonio[exr]: never skip there
else:
    OpenEXR = pytest.importorskip(
        "OpenEXR", reason="the OpenEXR bindings are not installed (pip install 'gonio[exr]')")


class Ramp:
    """A deterministic estimator whose value names its entry: 100 N.V + 10 alpha + eta (and
    minus that for a second channel), so a misplaced pixel shows."""

    description = "ramp"

    def __init__(self, channels):
        self.channels = channels

    def __call__(self, params, u, rng):
        value = 100 * params[:, 0] + 10 * params[:, 1] + (params[:, 2] if params.shape[1] > 2
                                                          else 0.0)
        return np.stack([value, -value][: len(self.channels)], axis=-1)


def read_raw(path):
    """Header and channel arrays straight from the bindings (not through gonio)."""
    with OpenEXR.File(str(path)) as f:
        header = dict(f.header())
        channels = {n: (np.array(c.pixels), c.type()) for n, c in f.channels().items()}
    return header, channels


def test_transmission_half_atlas_of_eta_slices(tmp_path):
    spec = TableSpec(kind="transmission", shape=(8, 5, 3), dtype="float16", samples=4,
                     tile_entries=7)
    table = bake(spec, Ramp(("transmittance",)))
    path = table.save(tmp_path / "t.exr")
    header, channels = read_raw(path)
    pixels, pixel_type = channels["R"]
    assert set(channels) == {"R"} and pixel_type == OpenEXR.HALF
    assert pixels.dtype == np.float16 and pixels.shape == (3 * 5, 8)  # height x width
    points = grid_points(spec).reshape(3 * 5, 8, 3)  # the model's (N.V, alpha, eta) per pixel
    alpha, eta = (a.values() for a in spec.axes[1:])
    for x, y in [(0, 0), (7, 0), (2, 4), (5, 5), (3, 14)]:  # N.V x, alpha y % 5, eta y // 5
        mu, a, e = points[y, x]
        assert (a, e) == (alpha[y % 5], eta[y // 5])
        assert pixels[y, x] == np.float16((100 * mu + 10 * a + e) * e * e)  # stores eta^2 T
    atlas = json.loads(header["gonio.atlas"])
    assert atlas["width"] == 8 and atlas["height"] == 15 and atlas["pixel_type"] == "HALF"
    assert atlas["channels"] == {"R": "transmittance"} and "y // 5" in atlas["layout"]
    axes = json.loads(header["gonio.axes"])
    assert [a["name"] for a in axes] == ["cos_theta", "alpha", "eta"]
    assert "sqrt(alpha)" in axes[1]["parameterisation"]
    assert json.loads(header["gonio.spec"]) == spec.to_dict()
    assert json.loads(header["gonio.model"]) == "ramp"
    loaded = load_table(path)
    assert loaded.data.dtype == np.float16 and loaded.data.tobytes() == table.data.tobytes()
    assert loaded.spec == spec and loaded.metadata() == table.metadata()


def test_reflection_float_round_trip_keeps_validation(tmp_path):
    spec = TableSpec(kind="reflection", shape=(4, 6), dtype="float32", samples=4)
    table = bake(spec, Ramp(("scale", "bias")))
    table.validation = {"entry_max": 0.1 + 0.2, "lookup_rms": 1e-300, "edge_points": None}
    path = table.save(tmp_path / "r.EXR")
    _, channels = read_raw(path)
    assert {n: t for n, (_, t) in channels.items()} == {"R": OpenEXR.FLOAT,
                                                         "G": OpenEXR.FLOAT}
    assert np.array_equal(channels["G"][0], -channels["R"][0])
    loaded = load_table(path)
    assert loaded.data.dtype == np.float32 and loaded.data.tobytes() == table.data.tobytes()
    assert loaded.validation == table.validation and loaded.metadata() == table.metadata()


def test_float64_and_foreign_files_are_refused(tmp_path):
    table = Table(spec=TableSpec(kind="reflection", shape=(2, 2), dtype="float64"),
                  data=np.zeros((2, 2, 2)))
    with pytest.raises(ValueError, match="float16 .HALF. or float32 .FLOAT., not float64"):
        table.save(tmp_path / "x.exr")
    assert not (tmp_path / "x.exr").exists()
    foreign = tmp_path / "plain.exr"
    with OpenEXR.File({"type": OpenEXR.scanlineimage}, {"R": np.zeros((2, 2), np.float32)}) as f:
        f.write(str(foreign))
    with pytest.raises(ValueError, match="not a gonio lookup table"):
        load_table(foreign)
    garbage = tmp_path / "garbage.exr"
    garbage.write_text("not an image")
    with pytest.raises(ValueError, match="not a readable OpenEXR file"):
        load_table(garbage)


def test_cli_writes_exr_and_refuses_float64_before_baking(tmp_path, capsys):
    args = ["lut", "--kind", "transmission", "--size", "4x3x2", "--samples", "16"]
    out = tmp_path / "t.exr"
    assert main([*args, "--out", str(out)]) == 0
    assert capsys.readouterr().out.splitlines()[-1] == str(out)
    table = load_table(out)
    npz = tmp_path / "t.npz"
    assert main([*args, "--out", str(npz)]) == 0
    capsys.readouterr()
    assert table.data.tobytes() == load_table(npz).data.tobytes()
    assert main([*args, "--dtype", "float64", "--out", str(tmp_path / "x.exr")]) == 2
    captured = capsys.readouterr()
    err = captured.err.strip()
    assert err.startswith("gonio lut: error:") and "not float64" in err and "\n" not in err
    assert "baked" not in captured.out and not (tmp_path / "x.exr").exists()


@pytest.mark.parametrize("remap", ["tir", "none"])
def test_atlas_sampling_recipe_of_the_docs_gives_the_trilinear_lookup(tmp_path, remap):
    """docs/lut.md's shader recipe (texture coordinates from N.V, alpha, eta, then two
    bilinear fetches in the atlas blended across eta) applied to the pixels read back from
    the file equals Table.lookup."""
    spec = TableSpec(kind="transmission", shape=(8, 5, 6), dtype="float32", samples=4,
                     remap=remap)
    table = bake(spec, Ramp(("transmittance",)))
    table.data = (table.data + np.random.default_rng(4).random(table.data.shape)).astype(
        np.float32)  # a ramp is multilinear already: add texel noise so blending shows
    _, channels = read_raw(table.save(tmp_path / "t.exr"))
    atlas = channels["R"][0].astype(np.float64)[..., None]
    n_mu, n_alpha, n_eta = spec.shape
    params = random_points(spec, 500, seed=5).T
    t = np.stack(texture_coords(spec, *params), axis=-1)
    t_alpha = np.clip(t[:, 1], 0.5 / n_alpha, 1 - 0.5 / n_alpha)
    x = np.clip(t[:, 2] * n_eta - 0.5, 0, n_eta - 1)
    k = np.minimum(np.floor(x), n_eta - 2)
    low, high = (interpolate(atlas, [(k + j + t_alpha) / n_eta, t[:, 0]]) for j in (0, 1))
    recipe = low + (x - k)[:, None] * (high - low)
    recipe = recipe / albedo_factor(spec.remapped, params[2])[:, None]  # stored eta^2 T
    assert np.allclose(recipe, table.lookup(*params), rtol=0, atol=1e-12)
