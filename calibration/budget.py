"""The GUM uncertainty budget of reduced BSDF values: named standard uncertainties, each either a
point's own (independent between points) or shared (one error common to many points), combined
by plain linear propagation, u^2 = sum of the components' squares (docs/fitting.md, "Uncertainty
budget"); and the angle terms, the stages' errors propagated through the model's local slope."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from calibration.type_b import repeatability_figures

#: The coverage factor of the expanded uncertainty U = k u unless meta["coverage_k"] says other.
COVERAGE_K = 2.0
#: Stage step of the central differences that give the model's slope, degrees: 1/100 of the
#: narrowest lobe the fits see (Beckmann 0.023, ~1.3 deg wide), so the curvature error is ~1e-4.
SLOPE_STEP_DEG = 0.01
#: The stages whose positions set a reading's directions (gonio.geometry.directions' arguments).
STAGE_ROLES = ("sample", "arm", "elevation", "azimuth")
#: The stages a calibration gives zero offsets for (calibration.calfile.Calibration).
OFFSET_ROLES = ("sample", "arm")


@dataclass
class Budget:
    """Components of N values, built up one by one: `own` (N,) absolute standard uncertainties
    independent between points, `shared` (N, k) absolute errors common to points (the values
    carry shared @ z, z ~ N(0, I_k)); the fit sees the shared ones as a covariance."""

    bsdf: np.ndarray
    own: dict[str, np.ndarray] = field(default_factory=dict)
    shared: dict[str, np.ndarray] = field(default_factory=dict)

    def add_own(self, name: str, u: np.ndarray) -> None:
        """An independent component (N,), 1/sr."""
        self.own[name] = np.abs(np.asarray(u, dtype=np.float64))

    def add_shared(self, name: str, errors: np.ndarray) -> None:
        """A shared component: (N, k) or (N,) errors, 1/sr, common to the points of a column."""
        errors = np.asarray(errors, dtype=np.float64)
        self.shared[name] = errors[:, None] if errors.ndim == 1 else errors

    @property
    def components(self) -> dict[str, np.ndarray]:
        """Every component's standard uncertainty (N,), 1/sr, by name (a name may have an own
        and a shared part: their root sum of squares)."""
        out = dict(self.own)
        for name, e in self.shared.items():
            out[name] = np.hypot(out.get(name, 0.0), np.linalg.norm(e, axis=1))
        return out

    @property
    def sigma(self) -> np.ndarray:
        """The combined standard uncertainty u."""
        parts = list(self.components.values())
        return np.sqrt(np.sum(np.square(parts), axis=0)) if parts else np.zeros(len(self.bsdf))

    @property
    def shared_rel(self) -> np.ndarray:
        """The shared errors relative to the values (ReducedData.shared_rel); 0 where the value
        is 0 or not finite (those points keep the error in their own part of sigma)."""
        if not self.shared:
            return np.zeros((len(self.bsdf), 0))
        errors = np.hstack(list(self.shared.values()))
        scale = np.abs(self.bsdf)[:, None]
        with np.errstate(divide="ignore", invalid="ignore"):
            rel = np.where((scale > 0) & np.isfinite(scale), errors / scale, 0.0)
        return np.where(np.isfinite(rel), rel, 0.0)


@dataclass(frozen=True)
class AngleInputs:
    """What the angle terms propagate, degrees (1-sigma) per stage role: each move's own
    scatter (the config's [axes.NAME] repeatability_deg, else the stage kind's declared
    figure: calibration.type_b) and the calibration's zero-offset uncertainty, common to every
    reading; `sources`: where each role's repeatability comes from."""

    repeatability_deg: dict[str, float] = field(default_factory=dict)
    offset_sigma_deg: dict[str, float] = field(default_factory=dict)
    sources: dict[str, str] = field(default_factory=dict)

    @classmethod
    def of_run(cls, config: dict, cal=None) -> AngleInputs:
        """From a run's stored instrument config and the calibration applied (if any)."""
        repeat = repeatability_figures(config, STAGE_ROLES)
        offsets = {}
        if cal is not None:
            for role in OFFSET_ROLES:
                value = getattr(cal, f"{role}_offset_deg")
                if value is not None:
                    offsets[role] = float(value.sigma)
        used = {r: f for r, f in repeat.items() if f.sigma > 0}
        return cls({r: f.sigma for r, f in used.items()},
                   {r: v for r, v in offsets.items() if v > 0},
                   {r: f.source for r, f in used.items()})

    @property
    def any(self) -> bool:
        """True when some angle uncertainty is stated."""
        return bool(self.repeatability_deg or self.offset_sigma_deg)

    def to_json(self) -> dict:
        """The inputs as meta records them."""
        return {"repeatability_deg": self.repeatability_deg,
                "offset_sigma_deg": self.offset_sigma_deg}


def stage_slopes(stages: dict[str, np.ndarray], roles: set[str],
                 reading: Callable[[dict[str, np.ndarray]], np.ndarray],
                 step_deg: float = SLOPE_STEP_DEG) -> dict[str, np.ndarray]:
    """d(reading)/d(stage) per degree, by central differences, for each role in `roles`;
    `reading(stages)` is what reduction would give if the stages stood at `stages`."""
    slopes = {}
    for role in sorted(roles):
        up, down = dict(stages), dict(stages)
        up[role] = stages[role] + step_deg
        down[role] = stages[role] - step_deg
        slopes[role] = (reading(up) - reading(down)) / (2.0 * step_deg)
    return slopes


def move_ids(readings: np.ndarray, rows: np.ndarray, role: str) -> np.ndarray:
    """For each of `rows` (sample readings), the number of the stage's move it was read after:
    over all readings in the order taken, a new move wherever the stage's reported angle
    differs from the reading before (beam and dark positions count: the stage went there)."""
    order = np.argsort(readings["index"], kind="stable")
    angle = readings[f"{role}_deg"][order]
    moves = np.concatenate([[0], np.cumsum(angle[1:] != angle[:-1])])
    of_index = dict(zip(readings["index"][order].tolist(), moves.tolist(), strict=True))
    return np.array([of_index[i] for i in rows["index"].tolist()], dtype=np.int64)


def add_angle_terms(budget: Budget, slopes: dict[str, np.ndarray], inputs: AngleInputs,
                    moves: dict[str, np.ndarray]) -> None:
    """angle_repeatability (each move's scatter: a point's own, shared by the points read
    without the stage moving between them, one column per such move) and angle_offset
    (shared: the calibration's zero offsets, one column per stage), from the slopes (1/sr
    per degree) and the move numbers of `move_ids`."""
    own, shared = [], []
    for role, sigma in inputs.repeatability_deg.items():
        error = slopes[role] * sigma
        _, first, counts = np.unique(moves[role], return_inverse=True, return_counts=True)
        alone = counts[first] == 1
        own.append(np.where(alone, error, 0.0))
        for group in np.flatnonzero(counts > 1):
            shared.append(np.where(first == group, error, 0.0))
    if own:
        budget.add_own("angle_repeatability", np.sqrt(np.sum(np.square(own), axis=0)))
    if shared:
        budget.add_shared("angle_repeatability", np.stack(shared, axis=1))
    offsets = [slopes[r] * s for r, s in inputs.offset_sigma_deg.items()]
    if offsets:
        budget.add_shared("angle_offset", np.stack(offsets, axis=1))


def expanded(data) -> tuple[float, np.ndarray]:
    """(k, U = k u) of a ReducedData: its meta's coverage factor (default COVERAGE_K)."""
    k = float(data.meta.get("coverage_k", COVERAGE_K))
    if not (math.isfinite(k) and k > 0):
        raise ValueError(f"coverage factor k must be a finite number > 0, got {k!r}")
    return k, k * data.sigma


def summary(data) -> dict:
    """The budget of a ReducedData per component, over its valid points with u > 0 and f != 0:
    `kind` (own or shared; None where the data do not say, as for an imported file), the median
    and largest share u_c / u, the median u_c / |f| and the `source` of a type-B figure (None
    for the ones the run's readings give); then k, the median U / |f|, the number
    of points summarised and the budget's notes. What `gonio reduce` prints and `gonio fit
    --json` gives as "budget" (None for a statistic of no points)."""
    good = data.valid & (data.sigma > 0) & (data.bsdf != 0) & np.isfinite(data.bsdf)
    budget = data.meta.get("budget")
    shared = set((budget or {}).get("shared", ()))
    sources = (budget or {}).get("sources", {})

    def median(x: np.ndarray) -> float | None:
        return float(np.median(x)) if len(x) else None

    components = {}
    for name, u in sorted(data.components.items()):
        share = np.asarray(u)[good] / data.sigma[good]
        components[name] = {
            "kind": None if budget is None else "shared" if name in shared else "own",
            "median_share": median(share),
            "max_share": float(share.max()) if len(share) else None,
            "median_relative": median(np.asarray(u)[good] / np.abs(data.bsdf[good])),
            "source": sources.get(name)}
    k, big_u = expanded(data)
    return {"components": components, "coverage_k": k,
            "median_expanded_relative": median(big_u[good] / np.abs(data.bsdf[good])),
            "points": int(good.sum()), "notes": list((budget or {}).get("notes", ()))}
