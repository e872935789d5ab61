"""The remapped N.V coordinate (model.lut.remap) and the fixed-index table: lookups at the
nodes equal direct evaluations of the model there, lookups are continuous across eta = 1, and
the map inverts."""

from __future__ import annotations

import numpy as np
import pytest

from model.lut import TableSpec, bake
from model.lut.bake import grid_points
from model.lut.model import ModelEstimator
from model.lut.remap import MU_FLOOR, nv_coord, nv_value
from model.lut.validate import reference, stored_values

REMAPPED = TableSpec(kind="transmission", shape=(12, 6, 6), dtype="float64", samples=512,
                     tile_entries=36)
FIXED = TableSpec(kind="transmission", shape=(12, 6), dtype="float64", samples=512,
                  tile_entries=36, eta=1.5)


@pytest.fixture(scope="module")
def tables():
    """The model's remapped 3-D table and its 2-D table at eta = 1.5 and 1 / 1.5."""
    return {spec.eta: bake(spec) for spec in (REMAPPED, FIXED)}


def test_the_map_inverts_and_keeps_its_nodes():
    rng = np.random.default_rng(2)
    mu, alpha = rng.random(4000), rng.random(4000) ** 2
    eta = np.exp(rng.uniform(np.log(0.4), np.log(2.5), 4000))
    t = nv_coord(mu, alpha, eta, 32)
    assert np.all((t >= 0.5 / 32) & (t <= 1 - 0.5 / 32))
    assert np.allclose(nv_value(t, alpha, eta, 32), mu, atol=1e-9)
    # monotonic in N.V at every (alpha, eta)
    grid = np.linspace(0, 1, 2001)
    for a, e in [(0.0, 0.5), (1e-4, 0.999), (0.05, 1.02), (0.3, 0.7), (1.0, 2.5)]:
        assert np.all(np.diff(nv_coord(grid, a, e, 32)) >= 0)
    # a smooth surface's critical angle sits on node n // 3
    eta = np.array([0.45, 0.7, 0.95])
    assert np.allclose(nv_coord(np.sqrt(1 - eta**2), 0.0, eta, 32) * 32 - 0.5, 32 // 3)


@pytest.mark.parametrize("fixed_eta", [None, 1.5])
def test_remapped_lookup_equals_a_direct_evaluation_at_the_nodes(tables, fixed_eta):
    """At each node's (N.V, alpha, eta) the lookup returns the node (the remap puts the point
    on it), and the node is the model's integral there (independent estimate, 8x samples)."""
    table = tables[fixed_eta]
    spec = table.spec
    points = grid_points(spec)
    at = points.copy()  # where a lookup lands on each node: N.V = 0, not the floor it is baked at
    at[:, 0] = np.where(points[:, 0] == MU_FLOOR, 0.0, points[:, 0])
    if fixed_eta is None:  # nodes beyond the split of an eta > 1 slice hold its mirror 1/eta
        slice_eta = np.broadcast_to(spec.axes[2].values()[:, None, None],
                                    spec.array_shape[:-1]).ravel()
        on_slice = np.isclose(points[:, 2], slice_eta, rtol=1e-12)
        assert 0 < (~on_slice).sum() < len(points) // 3
        looked_up = table.lookup(*at[on_slice].T)[:, 0]
    else:
        on_slice = np.ones(len(points), bool)
        # channel c is T at spec.etas[c], each with its own N.V remap: rows c, c + 2, ...
        assert np.allclose(points[:, 2], np.tile(spec.etas, len(points) // 2))
        looked_up = np.column_stack([table.lookup(at[c::2, 0], at[c::2, 1])[:, c]
                                     for c in (0, 1)]).ravel()
    stored = stored_values(table)[on_slice, 0]
    assert np.allclose(looked_up, stored, rtol=1e-6, atol=1e-6)  # t round trip: ~1e-8
    # within the bake's own Monte Carlo error at 512 points (largest beyond the critical
    # angle at eta = 0.4, where T is up to 6.25 and a few rough facets transmit)
    direct, _ = reference(points[on_slice], ModelEstimator("transmission"), 4096)
    err = np.abs(stored - direct[:, 0])
    assert err.max() < 0.03 and np.sqrt(np.mean(err**2)) < 6e-3


def test_lookups_are_continuous_across_eta_one(tables):
    table = tables[None]
    mu, alpha = np.meshgrid(np.linspace(1e-3, 1, 60), np.linspace(0, 1, 40))
    def jump(delta):
        below, above = (table.lookup(mu, alpha, np.full_like(mu, 1 + e))[..., 0]
                        for e in (-delta, delta))
        return np.max(np.abs(below - above))

    # the eta coordinate goes as |ln eta|^0.4 (model.lut.axes.ETA_POWER): continuous, steep
    jumps = [jump(d) for d in (1e-6, 1e-9, 1e-12, 1e-15)]
    assert np.all(np.diff(jumps) < 0) and jumps[-1] < 2e-5
    # and the texture coordinate itself
    t_below, t_above = (nv_coord(mu, alpha, 1 + e, 32) for e in (-1e-9, 1e-9))
    assert np.max(np.abs(t_below - t_above)) < 1e-4


def test_grazing_nodes_are_baked_at_the_limit():
    points = grid_points(REMAPPED)
    assert points[:, 0].min() == MU_FLOOR and np.all(points[:, 0] <= 1.0)
