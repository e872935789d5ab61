"""Validate a baked table: entries against converged integrals, and interpolated lookups at
random points (uniform in the physical N.V, alpha, eta) against direct integration there; max
and RMS absolute errors (for transmission also apart for the points near the
total-internal-reflection edge, those between the two eta nodes around eta = 1, and the rest).

The reference is two independent estimates with `reference_samples` Sobol points each (seeds
unrelated to the table's); their mean is the reference and their half difference is reported
as the reference's own noise, so an error near that noise means "no error detectable".
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass

import numpy as np

from model.lut.axes import ETA_MAX
from model.lut.bake import Estimator, grid_points, integrate_points
from model.lut.remap import albedo_factor
from model.lut.spec import TableSpec
from model.lut.table import Table

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
    unity_eta: tuple[float, float] | None = None  # the eta nodes bracketing eta = 1
    unity_points: int | None = None  # lookups with eta strictly between them
    unity_lookup_max: float | None = None
    unity_lookup_rms: float | None = None
    rest_lookup_max: float | None = None  # lookups in neither part
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
    """count parameter points (count, d), uniform in the physical N.V, alpha and eta over
    the table's domain (not in texture coordinates)."""
    u = np.random.default_rng(seed).random((count, len(spec.axes)))
    low = {"cos_theta": 0.0, "alpha": 0.0, "eta": 1.0 / ETA_MAX}
    high = {"cos_theta": 1.0, "alpha": 1.0, "eta": ETA_MAX}
    return np.stack([low[a.name] + (high[a.name] - low[a.name]) * u[:, k]
                     for k, a in enumerate(spec.axes)], axis=-1)


def model_points(spec: TableSpec, params: np.ndarray) -> np.ndarray:
    """The model parameters of the lookups at params (m, d), one row per looked-up value: a
    fixed-index table's lookup gives a value at each of its etas, (m * 2, 3)."""
    if spec.etas is None:
        return params
    return np.column_stack([np.repeat(params, len(spec.etas), axis=0),
                            np.tile(spec.etas, len(params))])


def near_critical(params: np.ndarray, band: float = TIR_BAND) -> np.ndarray:
    """True for transmission points (m, 3) seen from the denser side (eta < 1) whose N.V is
    within band of the critical sqrt(1 - eta^2), below which a smooth surface transmits
    nothing."""
    mu, eta = params[:, 0], params[:, 2]
    critical = np.sqrt(np.maximum(1.0 - eta * eta, 0.0))
    return (eta < 1.0) & (np.abs(mu - critical) <= band)


def chosen_entries(total: int, entries: int | None, seed: int) -> np.ndarray:
    """Flat indices of the entries to check among total: all, or a seeded random subset."""
    if entries is None or entries >= total:
        return np.arange(total)
    return np.sort(np.random.default_rng(seed).choice(total, size=entries, replace=False))


def max_rms(err: np.ndarray) -> tuple[float, float]:
    """Largest absolute error and root-mean-square error."""
    return float(np.max(np.abs(err))), float(np.sqrt(np.mean(err * err)))


def unity_bracket(spec: TableSpec) -> tuple[float, float] | None:
    """The eta nodes on either side of eta = 1 (None for a table without an eta axis)."""
    if len(spec.axes) < 3:
        return None
    etas = spec.axes[2].values()
    return float(etas[etas < 1.0].max()), float(etas[etas > 1.0].min())


def edge_split(params: np.ndarray, err: np.ndarray,
               bracket: tuple[float, float] | None = None) -> dict:
    """Lookup errors near the TIR edge, between the eta nodes bracketing eta = 1 (when given)
    and at the other points (ValidationReport fields; a part with no points has None)."""
    edge = near_critical(params)
    parts = {"edge": edge}
    out = {"tir_band": TIR_BAND, "edge_points": int(edge.sum())}
    if bracket is not None:
        unity = (params[:, 2] > bracket[0]) & (params[:, 2] < bracket[1])
        parts["unity"] = unity
        out |= {"unity_eta": bracket, "unity_points": int(unity.sum())}
    parts["rest"] = ~np.logical_or.reduce(list(parts.values()))
    for name, part in parts.items():
        worst, rms = max_rms(err[part]) if part.any() else (None, None)
        out |= {f"{name}_lookup_max": worst, f"{name}_lookup_rms": rms}
    return out


def stored_values(table: Table) -> np.ndarray:
    """The table's stored values in the units of the model's channels, one row per grid
    point (a remapped transmission table stores eta^2 T: divided out here)."""
    points = grid_points(table.spec)
    data = table.data.astype(np.float64).reshape(len(points), -1)
    if table.spec.kind != "transmission":
        return data
    return data / albedo_factor(table.spec.remapped, points[:, 2:3])


def validate(table: Table, estimator: Estimator | None = None, *, entries: int | None = None,
             points: int = 1000, reference_samples: int = 2**14, seed: int = 1,
             client=None) -> ValidationReport:
    """Check `entries` table entries (all when None, else a random subset) and `points`
    random lookups (uniform in the physical parameters over the whole domain)."""
    if estimator is None:
        from model.lut.estimators import estimator_for

        estimator = estimator_for(table.spec)
    start = time.perf_counter()
    grid = grid_points(table.spec)
    index = chosen_entries(len(grid), entries, seed)
    grid = grid[index]
    stored = stored_values(table)[index]
    params = random_points(table.spec, points, seed)
    looked_up = model_points(table.spec, params)
    ref, noise = reference(np.concatenate([grid, looked_up]), estimator, reference_samples,
                           client)
    entry_err = stored - ref[: len(grid)]
    lookup_err = table.lookup(*params.T).reshape(len(looked_up), -1) - ref[len(grid):]
    split = (edge_split(looked_up, lookup_err, unity_bracket(table.spec))
             if table.spec.kind != "reflection" else {})
    return ValidationReport(
        len(grid), *max_rms(entry_err), points, *max_rms(lookup_err),
        float(np.sqrt(np.mean(noise * noise))), reference_samples,
        time.perf_counter() - start, **split)


def fixed_index_error(fixed: Table, full: Table, etas: list[float], points: int = 2000,
                      seed: int = 1) -> list[dict]:
    """How far a fixed-index table is from the 3-D table when the glass's index is another:
    at each eta, max and RMS of the fixed table's channel on eta's side of 1 (T at
    fixed.spec.eta, or at its reciprocal) minus the 3-D table's lookup at eta, over points
    uniform in (N.V, alpha)."""
    mu, alpha = np.random.default_rng(seed).random((2, points))
    looked_up = fixed.lookup(mu, alpha)
    out = []
    for eta in etas:
        channel = 0 if (eta > 1) == (fixed.spec.eta > 1) else 1
        err = looked_up[:, channel] - full.lookup(mu, alpha, np.full(points, eta))[:, 0]
        worst, rms = max_rms(err)
        out.append({"eta": eta, "fixed_eta": fixed.spec.etas[channel], "max": worst,
                    "rms": rms})
    return out
