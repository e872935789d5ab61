"""Bake tables tile by tile with Dask: in-process threads, or any distributed Client.

A tile is a fixed run of `tile_entries` consecutive entries (C order); its random numbers come
only from (seed, tile index), so the table is the same to the last bit whatever the number of
workers, threads or machines. Each tile integrates with one scrambled Sobol point set of
`samples` points shared by its entries (smooth error across neighbouring entries).
"""

from __future__ import annotations

import time
from typing import Protocol

import numpy as np
from scipy.stats import qmc

from model.cluster import map_tasks, total_threads
from model.lut.remap import albedo_factor, node_points
from model.lut.spec import TableSpec
from model.lut.table import Table

#: Dask tasks per thread of the layout: enough to balance the load, few enough that the
#: per-task cost of a distributed scheduler (about a millisecond each) stays small.
TASKS_PER_THREAD = 8


class Estimator(Protocol):
    """Monte Carlo estimate of a table's channels at parameter points (m, d) from uniform
    points u (n, 3) in [0, 1)^3 (and rng for stochastic models): returns (m, channels)."""

    channels: tuple[str, ...]

    def __call__(self, params: np.ndarray, u: np.ndarray,
                 rng: np.random.Generator) -> np.ndarray: ...


def tile_generator(seed: int, tile: int) -> np.random.Generator:
    """The random generator of one tile: a function of (seed, tile index) only."""
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(tile,)))


def integrate_tile(params: np.ndarray, estimator: Estimator, samples: int, seed: int,
                   tile: int) -> np.ndarray:
    """Estimates for one tile's parameter points, from its own seeded Sobol set."""
    rng = tile_generator(seed, tile)
    u = qmc.Sobol(d=3, scramble=True, seed=rng).random(samples)
    out = np.asarray(estimator(params, u, rng), dtype=np.float64)
    if out.shape != (len(params), len(estimator.channels)):
        raise ValueError(f"estimator returned shape {out.shape}, expected "
                         f"{(len(params), len(estimator.channels))}")
    return out


def integrate_tiles(tiles: list[tuple]) -> np.ndarray:
    """integrate_tile over a run of tiles (one Dask task), results stacked in order."""
    return np.concatenate([integrate_tile(*tile) for tile in tiles], axis=0)


def tile_arguments(params: np.ndarray, estimator: Estimator, *, samples: int, seed: int,
                   tile_entries: int) -> list[tuple]:
    """integrate_tile's arguments for each tile of the points (m, d), in order."""
    params = np.ascontiguousarray(params, dtype=np.float64)
    return [(params[s:s + tile_entries], estimator, samples, seed, k)
            for k, s in enumerate(range(0, len(params), tile_entries))]


def integrate_points(params: np.ndarray, estimator: Estimator, *, samples: int, seed: int,
                     tile_entries: int, client=None, progress: bool = False) -> np.ndarray:
    """Estimates (m, channels) at parameter points (m, d) with Dask: the threaded scheduler
    when client is None, else the given distributed Client. Consecutive tiles go to one task,
    about TASKS_PER_THREAD tasks per Dask thread (a tile's result does not depend on its
    task, so neither do the bits)."""
    tiles = tile_arguments(params, estimator, samples=samples, seed=seed,
                           tile_entries=tile_entries)
    per_task = max(1, -(-len(tiles) // (TASKS_PER_THREAD * total_threads(client))))
    batches = [(tiles[i:i + per_task],) for i in range(0, len(tiles), per_task)]
    return np.concatenate(map_tasks(integrate_tiles, batches, client, progress), axis=0)


def grid_points(spec: TableSpec) -> np.ndarray:
    """Model parameters (N.V, alpha[, eta]) of every stored value, in the stored array's C
    order (N.V fastest): (entries, axes); a fixed-index table's two channels are two values
    per entry, (entries * 2, 3). A remapped table's N.V follows model.lut.remap.node_points."""
    axes = spec.axes
    grids = np.meshgrid(*(axis.coords() for axis in axes[::-1]), indexing="ij")
    coords = [g.ravel() for g in grids[::-1]]
    values = [axis.to_value(t) for axis, t in zip(axes, coords, strict=True)]
    if spec.etas is not None:
        coords = [np.repeat(t, len(spec.etas)) for t in coords]
        values = [np.repeat(v, len(spec.etas)) for v in values]
        values.append(np.tile(spec.etas, len(grids[0].ravel())))
    if spec.remapped:
        values[0], values[2] = node_points(coords[0], values[1], values[2], axes[0].size,
                                           mirror=spec.etas is None)
    return np.stack(values, axis=-1)


def bake(spec: TableSpec, estimator: Estimator | None = None, client=None,
         progress: bool = False) -> Table:
    """Bake the table of spec (the model's estimator unless one is given) with Dask."""
    if estimator is None:
        from model.lut.estimators import estimator_for

        estimator = estimator_for(spec)
    start = time.perf_counter()
    values = integrate_points(grid_points(spec), estimator, samples=spec.samples,
                              seed=spec.seed, tile_entries=spec.tile_entries, client=client,
                              progress=progress)
    seconds = time.perf_counter() - start
    points = grid_points(spec)
    if not np.all(np.isfinite(values)):
        bad = points[~np.all(np.isfinite(values), axis=1)][0]
        raise ValueError(f"non-finite table value at (N.V, alpha[, eta]) = {tuple(bad)}")
    if spec.kind == "transmission":
        values = values * albedo_factor(spec.remapped, points[:, 2:3])
    exact = values.reshape(spec.array_shape)
    return Table(spec=spec, data=exact.astype(spec.dtype), bake_seconds=seconds,
                 model=getattr(estimator, "description", repr(estimator)))
