"""Validate a baked table: entries against converged integrals, and interpolated lookups at
random points against direct integration there; max and RMS absolute errors (for
transmission also apart for the points near the total-internal-reflection edge and the rest).

The reference is two independent estimates with `reference_samples` Sobol points each (seeds
unrelated to the table's); their mean is the reference and their half difference is reported
as the reference's own noise, so an error near that noise means "no error detectable".
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass

import numpy as np

from sim.lut.bake import Estimator, grid_points, integrate_points
from sim.lut.spec import TableSpec
from sim.lut.table import Table

#: Seeds of the two reference estimates (never used for baking: tables use small seeds).
REFERENCE_SEEDS = (0x5EED_0001_0000, 0x5EED_0002_0000)
#: Points per reference tile.
REFERENCE_TILE = 64
#: Half-width in N.V of the total-internal-reflection edge band (eta < 1) whose lookup errors
#: are reported apart: a regular N.V grid cannot follow the critical angle there.
TIR_BAND = 0.05


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
    tir_band: float | None = None  # transmission: half-width in N.V of the TIR edge band
    edge_points: int | None = None  # lookups with eta < 1 and |N.V - N.V_c| <= tir_band
    edge_lookup_max: float | None = None
    edge_lookup_rms: float | None = None
    rest_lookup_max: float | None = None
    rest_lookup_rms: float | None = None

    def to_dict(self) -> dict:
        """JSON-ready fields."""
        return asdict(self)


def reference(params: np.ndarray, estimator: Estimator, samples: int,
              client=None) -> tuple[np.ndarray, np.ndarray]:
    """Converged values at params (m, d): mean of two independent estimates, and their half
    difference (the reference's own noise)."""
    a, b = (integrate_points(params, estimator, samples=samples, seed=s,
                             tile_entries=REFERENCE_TILE, client=client)
            for s in REFERENCE_SEEDS)
    return 0.5 * (a + b), 0.5 * (a - b)


def random_points(spec: TableSpec, count: int, seed: int) -> np.ndarray:
    """count parameter points (count, d), uniform in texture coordinates over the domain."""
    t = np.random.default_rng(seed).random((count, len(spec.axes)))
    return np.stack([a.to_value(t[:, k]) for k, a in enumerate(spec.axes)], axis=-1)


def near_critical(params: np.ndarray, band: float = TIR_BAND) -> np.ndarray:
    """True for transmission points (m, 3) seen from the denser side (eta < 1) whose N.V is
    within band of the critical sqrt(1 - eta^2), below which a smooth surface transmits
    nothing."""
    mu, eta = params[:, 0], params[:, 2]
    critical = np.sqrt(np.maximum(1.0 - eta * eta, 0.0))
    return (eta < 1.0) & (np.abs(mu - critical) <= band)


def chosen_entries(spec: TableSpec, entries: int | None, seed: int) -> np.ndarray:
    """Flat indices of the entries to check: all, or a seeded random subset."""
    total = int(np.prod(spec.shape))
    if entries is None or entries >= total:
        return np.arange(total)
    return np.sort(np.random.default_rng(seed).choice(total, size=entries, replace=False))


def max_rms(err: np.ndarray) -> tuple[float, float]:
    """Largest absolute error and root-mean-square error."""
    return float(np.max(np.abs(err))), float(np.sqrt(np.mean(err * err)))


def edge_split(params: np.ndarray, err: np.ndarray) -> dict:
    """Lookup errors near the TIR edge and elsewhere (ValidationReport fields; a part with no
    points has None)."""
    edge = near_critical(params)
    parts = {"edge": err[edge], "rest": err[~edge]}
    out = {"tir_band": TIR_BAND, "edge_points": int(edge.sum())}
    for name, part in parts.items():
        worst, rms = max_rms(part) if part.size else (None, None)
        out |= {f"{name}_lookup_max": worst, f"{name}_lookup_rms": rms}
    return out


def validate(table: Table, estimator: Estimator | None = None, *, entries: int | None = None,
             points: int = 1000, reference_samples: int = 2**14, seed: int = 1,
             client=None) -> ValidationReport:
    """Check `entries` table entries (all when None, else a random subset) and `points`
    random lookups (uniform in texture coordinates over the whole domain)."""
    if estimator is None:
        from sim.lut.estimators import estimator_for

        estimator = estimator_for(table.spec)
    start = time.perf_counter()
    index = chosen_entries(table.spec, entries, seed)
    grid = grid_points(table.spec)[index]
    stored = table.data.astype(np.float64).reshape(-1, len(table.spec.channels))[index]
    params = random_points(table.spec, points, seed)
    ref, noise = reference(np.concatenate([grid, params]), estimator, reference_samples, client)
    entry_err = stored - ref[: len(grid)]
    lookup_err = table.lookup(*params.T) - ref[len(grid):]
    split = edge_split(params, lookup_err) if table.spec.kind != "reflection" else {}
    return ValidationReport(
        len(grid), *max_rms(entry_err), points, *max_rms(lookup_err),
        float(np.sqrt(np.mean(noise * noise))), reference_samples,
        time.perf_counter() - start, **split)
