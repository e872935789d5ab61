"""Large sweeps of simulated measurements: every combination of bench settings (sample, source,
aperture, alignment, detector) times every combination of stage positions, one Dask task per
setting, detector noise seeded per setting so any worker layout gives the same numbers.

The physics is the emulated bench's own: sim.bench.build_power_source gives the true power at
the detector, sim.devices.photodiode.PhotodiodeModel turns it into the meter's reading.
"""

from __future__ import annotations

import copy
import itertools
import json
import time
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from model.cluster import map_tasks
from sim.bench import build_power_source
from sim.devices.photodiode import PhotodiodeModel

#: [sim] tables a sweep may vary (owned by sim.bench and sim.devices.photodiode).
TABLES = ("source", "sample", "aperture", "alignment", "stray", "detector")
#: Stage roles of a measurement position, in output order, and their defaults (degrees).
ROLES = {"sample": None, "arm": None, "elevation": 0.0, "azimuth": 0.0}
#: Per position: true power, the meter's reading, its range (all W) and the clip flag.
QUANTITIES = ("power_w", "reading_w", "range_w", "saturated")


@dataclass(frozen=True)
class Sweep:
    """base: the [sim] table every setting starts from; vary: "table.key" -> values (output
    axes, in order); positions: role -> angles in degrees (every combination)."""

    base: dict
    vary: dict[str, list] = field(default_factory=dict)
    positions: dict[str, list[float]] = field(default_factory=dict)
    seed: int = 0
    averaging: int = 1

    @property
    def shape(self) -> tuple[int, ...]:
        """Output shape: one axis per varied key, then one per stage role."""
        return (*(len(v) for v in self.vary.values()), *(len(p) for p in self.positions.values()))

    def settings(self) -> list[dict]:
        """The [sim] table of every combination of the varied values, C order."""
        out = []
        for combo in itertools.product(*self.vary.values()):
            cfg = copy.deepcopy(self.base)
            for key, value in zip(self.vary, combo, strict=True):
                table, name = key.split(".")
                cfg.setdefault(table, {})[name] = value
            out.append(cfg)
        return out

    def position_list(self) -> list[dict[str, float]]:
        """Every combination of stage positions, C order, as {"sample", "arm", ...} dicts."""
        roles = list(self.positions)
        return [dict(zip(roles, combo, strict=True))
                for combo in itertools.product(*self.positions.values())]


def _list(where: str, value: object) -> list:
    if not isinstance(value, list) or not value:
        raise ValueError(f"{where}: must be a non-empty list, got {value!r}")
    return value


def _angles(where: str, value: object) -> list[float]:
    values = _list(where, value)
    if not all(isinstance(v, (int, float)) and not isinstance(v, bool) and np.isfinite(v)
               for v in values):
        raise ValueError(f"{where}: must be a list of angles in degrees, got {value!r}")
    return [float(v) for v in values]


def parse_sweep(doc: Mapping, base_dir: Path = Path(".")) -> Sweep:
    """A Sweep from a parsed sweep file; every setting is checked by building its bench."""
    known = {"instrument", "seed", "averaging", "sim", "vary", "positions"}
    unknown = sorted(set(doc) - known)
    if unknown:
        raise ValueError(f"unknown key {unknown[0]!r}; known: {', '.join(sorted(known))}")
    base: dict = {}
    if "instrument" in doc:
        path = base_dir / str(doc["instrument"])
        try:
            base = tomllib.loads(path.read_text()).get("sim", {})
        except (OSError, tomllib.TOMLDecodeError) as exc:
            raise ValueError(f"instrument {str(path)!r}: {exc}") from None
    for table, values in doc.get("sim", {}).items():
        if not isinstance(values, Mapping):
            raise ValueError(f"[sim.{table}]: must be a table")
        base.setdefault(table, {}).update(values)
    vary = {}
    for key, values in doc.get("vary", {}).items():
        table, _, name = key.partition(".")
        if table not in TABLES or not name or "." in name:
            raise ValueError(f"[vary] {key!r}: must be <table>.<key> with table one of "
                             f"{', '.join(TABLES)}")
        vary[key] = _list(f"[vary] {key!r}", values)
    positions_doc = doc.get("positions", {})
    extra = sorted(set(positions_doc) - {f"{r}_deg" for r in ROLES})
    if extra:
        raise ValueError(f"[positions]: unknown key {extra[0]!r}; known: "
                         f"{', '.join(f'{r}_deg' for r in ROLES)}")
    positions = {}
    for role, default in ROLES.items():
        value = positions_doc.get(f"{role}_deg", None if default is None else [default])
        if value is None:
            raise ValueError(f"[positions]: missing required key '{role}_deg'")
        positions[role] = _angles(f"[positions] {role}_deg", value)
    seed, averaging = doc.get("seed", 0), doc.get("averaging", 1)
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed < 2**63:
        raise ValueError(f"seed: must be an integer in [0, 2^63), got {seed!r}")
    if isinstance(averaging, bool) or not isinstance(averaging, int) or averaging < 1:
        raise ValueError(f"averaging: must be an integer >= 1, got {averaging!r}")
    sweep = Sweep(base, vary, positions, seed, averaging)
    for k, cfg in enumerate(sweep.settings()):
        try:
            _instruments(cfg, 0)
        except ValueError as exc:
            raise ValueError(f"setting {k} ({_describe(sweep, k)}): {exc}") from None
    return sweep


def load_sweep(path: str | Path) -> Sweep:
    """Read and check a sweep TOML file (paths in it are relative to the file)."""
    path = Path(path)
    try:
        doc = tomllib.loads(path.read_text())
    except (OSError, tomllib.TOMLDecodeError) as exc:
        raise ValueError(f"{path}: {exc}") from None
    try:
        return parse_sweep(doc, path.parent)
    except ValueError as exc:
        raise ValueError(f"{path}: {exc}") from None


def _describe(sweep: Sweep, k: int) -> str:
    index = np.unravel_index(k, [len(v) for v in sweep.vary.values()]) if sweep.vary else ()
    return ", ".join(f"{key}={values[i]!r}"
                     for (key, values), i in zip(sweep.vary.items(), index, strict=True))


def _instruments(sim_config: dict, seed: int):
    """The bench's power source (positions set per call) and the detector model."""
    where: dict[str, float] = {}
    source = build_power_source(sim_config, lambda: where, clock=lambda: 0.0)
    meter = PhotodiodeModel(sim_config.get("detector"), seed=seed)
    return source, meter, where


def setting_seed(seed: int, k: int) -> int:
    """Detector-noise seed of setting k: a function of (sweep seed, k) only."""
    return int(np.random.SeedSequence(seed, spawn_key=(k,)).generate_state(1, np.uint64)[0])


def measure_setting(sim_config: dict, positions: list[dict[str, float]], seed: int,
                    averaging: int) -> np.ndarray:
    """(positions, 4): true power, reading, range (W) and saturated flag at each position."""
    source, meter, where = _instruments(sim_config, seed)
    wavelength = float(sim_config.get("source", {}).get("wavelength_nm", 632.8))
    out = np.empty((len(positions), len(QUANTITIES)))
    for j, pos in enumerate(positions):
        where.clear()
        where.update(pos)
        power = source.power_w()
        m = meter.measure(power, averaging=averaging, wavelength_nm=wavelength)
        out[j] = power, m.reading_w, m.range_w, m.saturated
    return out


@dataclass
class SweepResult:
    """Arrays of shape sweep.shape per quantity, and how long the sweep took."""

    sweep: Sweep
    values: dict[str, np.ndarray]
    seconds: float

    def save(self, path: str | Path, layout: str = "") -> Path:
        """.npz: one array per quantity, one `vary_<key>` / `<role>_deg` array per axis, and
        a JSON `metadata` string (base [sim] table, axes in order, seed, run time)."""
        s = self.sweep
        axes = {f"vary_{k}": np.asarray(v) for k, v in s.vary.items()}
        axes.update({f"{r}_deg": np.asarray(v) for r, v in s.positions.items()})
        meta = {"format": "gonio-sweep/1", "base_sim": s.base,
                "axes": [*(f"vary_{k}" for k in s.vary), *(f"{r}_deg" for r in s.positions)],
                "quantities": list(QUANTITIES), "seed": s.seed, "averaging": s.averaging,
                "seconds": self.seconds, "layout": layout}
        path = Path(path)
        with open(path, "wb") as fh:
            np.savez(fh, metadata=np.array(json.dumps(meta, default=str)), **axes,
                     **self.values)
        return path


def run_sweep(sweep: Sweep, client=None, progress: bool = False) -> SweepResult:
    """Measure every setting at every position, one Dask task per setting."""
    start = time.perf_counter()
    positions = sweep.position_list()
    tasks = [(cfg, positions, setting_seed(sweep.seed, k), sweep.averaging)
             for k, cfg in enumerate(sweep.settings())]
    rows = np.stack(map_tasks(measure_setting, tasks, client, progress))
    values = {q: rows[..., i].reshape(sweep.shape) for i, q in enumerate(QUANTITIES)}
    values["saturated"] = values["saturated"].astype(bool)
    return SweepResult(sweep, values, time.perf_counter() - start)
