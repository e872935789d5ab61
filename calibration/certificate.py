"""A reference standard's certificate (a TOML file): its BRDF or reflectance factor on a grid of
wavelength and geometry, with expanded uncertainty, read with one error per malformed field and
interpolated multilinearly inside the grid only (docs/calibration.md, "Reference standards")."""

from __future__ import annotations

import datetime
import hashlib
import itertools
import math
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from calibration.values import CalibrationError
from drivers.user_file import SETTINGS_FILE_CAP, read_user_file, user_text
from gonio.fields import Fields

FORMAT = "gonio-reference-certificate/1"
#: What a certificate states: the BRDF f in 1/sr, or the reflectance factor R = pi f.
QUANTITIES = ("brdf", "reflectance_factor")
#: A point's coordinates, in the order of the grid's axes; phi_deg may be left out (the values
#: then hold at every azimuth).
AXES = ("wavelength_nm", "theta_i_deg", "theta_o_deg", "phi_deg")
#: How far past an axis' end a point may lie and be taken at the end: a stage's zero offset
#: moves the angles by tenths of a degree, a wavelength is stated to a nanometre.
EDGE_TOLERANCE = {"wavelength_nm": 1.0, "theta_i_deg": 0.5, "theta_o_deg": 0.5, "phi_deg": 0.5}
#: Each axis' physical range.
AXIS_RANGE = {"wavelength_nm": (1.0, 100_000.0), "theta_i_deg": (0.0, 90.0),
              "theta_o_deg": (0.0, 90.0), "phi_deg": (0.0, 180.0)}
#: The most points a certificate may hold (a fine spectral and angular grid is a few thousand).
MAX_POINTS = 100_000


@dataclass(frozen=True)
class Certificate:
    """A certificate's identity and its grid: `axes` (name -> increasing values, AXES present),
    `value` and `expanded` (the stated quantity and its U, on the grid, axes in that order)."""

    id: str
    issuer: str
    date: str
    quantity: str
    coverage_k: float
    axes: dict[str, np.ndarray]
    value: np.ndarray
    expanded: np.ndarray
    file: str
    sha256: str
    description: str = ""

    def brdf_at(self, wavelength_nm: float, theta_i_deg: np.ndarray, theta_o_deg: np.ndarray,
                phi_deg: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(f, u): the certified BRDF (1/sr) and its standard uncertainty at each geometry,
        multilinear between grid points (phi: the azimuth from the plane of incidence, 180 on
        the specular side); a CalibrationError names the first point outside the grid."""
        n = len(np.asarray(theta_i_deg))
        query = {"wavelength_nm": np.full(n, float(wavelength_nm)),
                 "theta_i_deg": np.asarray(theta_i_deg, float),
                 "theta_o_deg": np.asarray(theta_o_deg, float),
                 "phi_deg": np.asarray(phi_deg, float)}
        weights = [self._axis_weights(name, query[name]) for name in self.axes]
        value, expanded = np.zeros(n), np.zeros(n)
        for corner in itertools.product((0, 1), repeat=len(weights)):
            index = tuple(w[2 * c] for w, c in zip(weights, corner, strict=True))
            weight = np.prod([w[2 * c + 1] for w, c in zip(weights, corner, strict=True)], axis=0)
            value += weight * self.value[index]
            expanded += weight * self.expanded[index]
        per_brdf = 1.0 / math.pi if self.quantity == "reflectance_factor" else 1.0
        return value * per_brdf, expanded * per_brdf / self.coverage_k

    def _axis_weights(self, name: str, x: np.ndarray) -> tuple[np.ndarray, ...]:
        """(lower index, its weight, upper index, its weight) of each x on the axis `name`,
        with x within EDGE_TOLERANCE of an end taken at the end; beyond that, refused."""
        grid = self.axes[name]
        outside = (x < grid[0] - EDGE_TOLERANCE[name]) | (x > grid[-1] + EDGE_TOLERANCE[name])
        if outside.any():
            bad = float(x[np.argmax(outside)])
            span = (f"{grid[0]:g}" if len(grid) == 1 else f"{grid[0]:g} to {grid[-1]:g}")
            raise CalibrationError(f"{self.file}: certificate {self.id!r} covers {name} "
                                   f"{span} only; a point at {name} {bad:g} is outside it")
        x = np.clip(x, grid[0], grid[-1])
        if len(grid) == 1:
            zero = np.zeros(len(x), dtype=np.intp)
            return zero, np.ones(len(x)), zero, np.zeros(len(x))
        upper = np.clip(np.searchsorted(grid, x, side="right"), 1, len(grid) - 1)
        t = (x - grid[upper - 1]) / (grid[upper] - grid[upper - 1])
        return upper - 1, 1.0 - t, upper, t

    def to_json(self) -> dict[str, Any]:
        """What a calibration file records of the certificate it came from."""
        return {"id": self.id, "issuer": self.issuer, "date": self.date,
                "quantity": self.quantity, "coverage_k": self.coverage_k,
                "file": self.file, "sha256": self.sha256}


def load(path: str | Path) -> Certificate:
    """Read and check a certificate file; one CalibrationError naming the file and the field."""
    path = Path(path)
    data = read_user_file(path, "certificate", SETTINGS_FILE_CAP, CalibrationError)
    try:
        table = tomllib.loads(user_text(data, path, "certificate", CalibrationError))
    except tomllib.TOMLDecodeError as exc:
        raise CalibrationError(f"{path}: not valid TOML ({exc})") from None
    return parse(table, str(path.resolve()), hashlib.sha256(data).hexdigest())


def parse(table: dict[str, Any], where: str, sha256: str) -> Certificate:
    """A certificate from its parsed TOML table (`where`: the file, for errors and the record)."""
    f = Fields(table, where, CalibrationError)
    if f.string("format") != FORMAT:
        raise f.fail("format", f"must be {FORMAT!r}")
    cert_id = f.string("id")
    if not cert_id.strip():
        raise f.fail("id", "must not be empty")
    issuer = f.string("issuer")
    date = f.table.get("date") if f.has("date") else None
    if not isinstance(date, str | datetime.date) or not str(date).strip():
        raise f.fail("date", f"must be a date (2026-01-31) or a string, got {date!r}")
    quantity = f.string("quantity", choices=QUANTITIES)
    k = f.number("coverage_k", low=0.0, high=10.0, low_open=True)
    description = f.string("description", "")
    rows = f.table.get("point") if f.has("point") else None
    if not isinstance(rows, list) or not rows:
        raise f.fail("point", "must be a non-empty array of tables ([[point]] wavelength_nm, "
                     "theta_i_deg, theta_o_deg, [phi_deg,] value, U)")
    if len(rows) > MAX_POINTS:
        raise f.fail("point", f"has {len(rows)} points; at most {MAX_POINTS}")
    f.done()
    points = [_point(row, where, i) for i, row in enumerate(rows)]
    axes, value, expanded = _grid(points, where)
    return Certificate(cert_id, issuer, str(date), quantity, float(k), axes, value, expanded,
                       where, sha256, description)


def _point(row: Any, where: str, i: int) -> dict[str, float]:
    """One [[point]]: its coordinates, value > 0 and U >= 0."""
    f = Fields(row, where, CalibrationError, f"point[{i}]")
    point = {name: f.number(name, low=lo, high=hi) for name, (lo, hi) in AXIS_RANGE.items()
             if name != "phi_deg" or f.has("phi_deg")}
    point["value"] = f.number("value", low=0.0, low_open=True)
    point["U"] = f.number("U", low=0.0)
    f.done()
    return point


def _grid(points: list[dict[str, float]], where: str
          ) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray]:
    """The points as a full grid: each axis' distinct values, and value and U at every
    combination; a CalibrationError names a point missing from the grid or given twice."""
    names = [n for n in AXES if n in points[0]]
    for i, p in enumerate(points):
        if [n for n in AXES if n in p] != names:
            raise CalibrationError(f"{where}: [point[{i}]]: every point must give the same "
                                   f"coordinates ({', '.join(names)}), as the first does")
    axes = {n: np.unique([p[n] for p in points]) for n in names}
    shape = tuple(len(a) for a in axes.values())
    value, expanded = np.full(shape, np.nan), np.full(shape, np.nan)
    for i, p in enumerate(points):
        index = tuple(int(np.searchsorted(axes[n], p[n])) for n in names)
        if not math.isnan(value[index]):
            raise CalibrationError(f"{where}: [point[{i}]]: a second point at "
                                   + _at(names, p))
        value[index], expanded[index] = p["value"], p["U"]
    if np.isnan(value).any():
        missing = np.argwhere(np.isnan(value))[0]
        at = {n: float(axes[n][j]) for n, j in zip(names, missing, strict=True)}
        raise CalibrationError(f"{where}: [point]: the points must fill a grid (every "
                               f"combination of the axes' values); none at {_at(names, at)}")
    return axes, value, expanded


def _at(names: list[str], point: dict[str, float]) -> str:
    return ", ".join(f"{n} {point[n]:g}" for n in names)
