"""Validate a baked table: entries against converged integrals, and interpolated lookups at
random points against direct integration there; max and RMS absolute errors.

The reference is two independent estimates with `reference_samples` Sobol points each (seeds
unrelated to the table's); their mean is the reference and their spread is reported as the
reference's own noise, so an error figure near that noise means "no error detectable".
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass

import numpy as np

from sim.lut.bake import Estimator, grid_points, integrate_points
from sim.lut.table import Table

#: Offset added to the table's seed for the two reference estimates (never a baking seed).
REFERENCE_SEEDS = (0x5EED_0001, 0x5EED_0002)


@dataclass(frozen=True)
class ValidationReport:
    """Absolute errors of the stored table (dtype rounding included) and of its lookups."""

    entries_checked: int
    entry_max: float
    entry_rms: float
    points_checked: int
    lookup_max: float
    lookup_rms: float
    reference_noise_rms: float
    reference_samples: int
    seconds: float

    def to_dict(self) -> dict:
        """JSON-ready fields."""
        return asdict(self)


def _reference(params: np.ndarray, estimator: Estimator, table: Table, samples: int,
               client) -> tuple[np.ndarray, np.ndarray]:
    """Mean of two independent converged estimates, and their half difference."""
    a, b = (integrate_points(params, estimator, samples=samples, seed=table.spec.seed + s,
                             tile_entries=table.spec.tile_entries, client=client)
            for s in REFERENCE_SEEDS)
    return 0.5 * (a + b), 0.5 * (a - b)


def _max_rms(err: np.ndarray) -> tuple[float, float]:
    return float(np.max(np.abs(err))), float(np.sqrt(np.mean(err * err)))


def validate(table: Table, estimator: Estimator | None = None, *, entries: int | None = None,
             points: int = 1000, reference_samples: int = 2**14, seed: int = 1,
             client=None) -> ValidationReport:
    """Check `entries` table entries (all when None, else a random subset) and `points`
    random lookups (uniform in texture coordinates over the whole domain)."""
    if estimator is None:
        from sim.lut.model import ModelEstimator

        estimator = ModelEstimator.for_spec(table.spec)
    start = time.perf_counter()
    rng = np.random.default_rng(seed)
    grid = grid_points(table.spec)
    stored = table.data.astype(np.float64).reshape(len(grid), -1)
    if entries is not None and entries < len(grid):
        chosen = np.sort(rng.choice(len(grid), size=entries, replace=False))
        grid, stored = grid[chosen], stored[chosen]
    t = rng.random((points, len(table.spec.axes)))
    params = np.stack([a.to_value(t[:, k]) for k, a in enumerate(table.spec.axes)], axis=-1)
    reference, noise = _reference(np.concatenate([grid, params]), estimator, table,
                                  reference_samples, client)
    entry_err = stored - reference[: len(grid)]
    lookup_err = table.lookup(*params.T) - reference[len(grid):]
    return ValidationReport(
        len(grid), *_max_rms(entry_err), points, *_max_rms(lookup_err),
        float(np.sqrt(np.mean(noise * noise))), reference_samples,
        time.perf_counter() - start)
