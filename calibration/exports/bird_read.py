"""Reading a BiRD universal BRDF file (calibration.exports.bird's or another lab's) into the
arrays of a ReducedData: the four angles (deg, ° or rad), BRDF, its uncertainty (uBRDF per
point, else BRDF's one stated uncertainty, in 1/sr or %), the wavelength, and gonio's ad-hoc
variables (u_NAME, shared_error_J, valid, flags) and adhoc_section (the record and the
reduction's facts) where the file has them. A spectral or polarised file (several wavelengths
or polarisation states) is refused, naming them, as gonio's fit takes one. A file that is not
one, or holds more than an import does (calibration.formats.limits, and the JSON caps below,
checked before the file is parsed), is one CalibrationError naming the field or the count.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from calibration.exports.bird import FACTS_KEY, RECORD_KEY, SHARED_PREFIX
from calibration.formats.limits import MAX_POINTS, MeasuredFile, check_count, measured_file
from calibration.values import CalibrationError

ANGLES = ("theta_i", "phi_i", "theta_r", "phi_r")
TO_DEGREES = {"deg": 1.0, "°": 1.0, "rad": math.degrees(1.0)}


@dataclass
class BirdData:
    """A BiRD file's points: angles in degrees, BRDF and its u in 1/sr (u None: the file
    states none), and what gonio's own files add."""

    angles_deg: dict[str, np.ndarray]
    brdf: np.ndarray
    sigma: np.ndarray | None
    wavelength_nm: float | None = None
    components: dict[str, np.ndarray] = field(default_factory=dict)
    shared_rel: np.ndarray | None = None
    valid: np.ndarray | None = None
    flags: np.ndarray | None = None
    record: dict[str, Any] = field(default_factory=dict)
    facts: dict[str, Any] = field(default_factory=dict)


#: The most JSON values (numbers, strings, true/false/null, keys, lists and objects) a BiRD
#: file may hold, and the most strings and the most lists and objects among them: parsed, a
#: number costs about 32 bytes, a short string about 90, a list or an object more, so that
#: parsing any file within MAX_FILE_BYTES stays within a few hundred MB. 24 values and 4
#: strings a point hold gonio's own export of MAX_POINTS points (flags and polarisations).
MAX_JSON_VALUES = 24 * MAX_POINTS
MAX_JSON_STRINGS = 4 * MAX_POINTS
MAX_JSON_CONTAINERS = 100_000


def read_bird(source: str | Path | MeasuredFile) -> BirdData:
    """The points of a BiRD file (see the module docstring), its size checked against
    calibration.formats.limits and the caps above before it is parsed."""
    file = measured_file(source)
    path = file.path
    _check_json_size(file)
    try:
        document = json.loads(file.data)
    except UnicodeDecodeError as exc:
        raise CalibrationError(f"{path}: not a readable text file ({exc})") from None
    except (ValueError, RecursionError) as exc:
        raise CalibrationError(f"{path}: not JSON ({exc})") from None
    reader = _Reader(path)
    data = reader.table(document, "data", "")
    brdf = reader.numbers(reader.table(data, "BRDF", "data"), "data.BRDF")
    n = len(brdf)
    angles = {}
    for name in ANGLES:
        variable = reader.table(data, name, "data")
        unit = variable.get("unit")
        if unit not in TO_DEGREES:
            raise reader.error(f"data.{name}.unit", f"must be one of {', '.join(TO_DEGREES)}, "
                                                    f"got {unit!r}")
        angles[name] = reader.numbers(variable, f"data.{name}", n) * TO_DEGREES[unit]
    out = BirdData(angles, brdf, _uncertainty(reader, data, brdf))
    wavelengths = data.get("wavelength_i")
    values = (np.unique(reader.numbers(wavelengths, "data.wavelength_i", n))
              if isinstance(wavelengths, dict) else np.empty(0))
    _check_one_state(reader, data, n, values)
    scale = {"nm": 1.0, "μm": 1000.0}.get(wavelengths.get("unit")) if len(values) else None
    if scale is not None:
        out.wavelength_nm = float(values[0]) * scale
    _adhoc(reader, data.get("adhoc_variables") or {}, n, out)
    adhoc = (document.get("metadata") or {}).get("adhoc_section") or {}
    out.record = adhoc.get(RECORD_KEY) or {}
    out.facts = adhoc.get(FACTS_KEY) or {}
    return out


def _check_one_state(reader: _Reader, data: dict, n: int, wavelengths: np.ndarray) -> None:
    """One error naming what a spectral or polarised file holds more than one of (the distinct
    `wavelengths`, incident or reflected polarisations): gonio's fit takes one wavelength and
    one polarisation state, so a file of several is refused rather than merged."""
    several = []
    if len(wavelengths) > 1:
        several.append(f"{len(wavelengths)} wavelengths in data.wavelength_i "
                       f"({', '.join(f'{v:g}' for v in wavelengths)} "
                       f"{data['wavelength_i'].get('unit')})")
    for name in ("polarization_i", "polarization_r"):
        if isinstance(data.get(name), dict):
            states = sorted({str(v) for v in reader.values(data[name], f"data.{name}", n)})
            if len(states) > 1:
                several.append(f"{len(states)} polarisations in data.{name} "
                               f"({', '.join(states)})")
    if several:
        raise CalibrationError(f"{reader.path}: holds {' and '.join(several)}; gonio's fit "
                               "takes one wavelength and one polarisation state: import one "
                               "part of the file at a time")


def _check_json_size(file: MeasuredFile) -> None:
    """One error naming the file if it holds more JSON values, strings, or lists and objects
    than the caps, counted from its separators, quotes and brackets (an upper bound: those
    inside strings count too) without parsing it."""
    data = file.data
    containers = data.count(b"[") + data.count(b"{")
    check_count(file.path, containers, "JSON lists and objects (counted by their brackets)",
                MAX_JSON_CONTAINERS)
    check_count(file.path, data.count(b'"') // 2, "JSON strings (counted by their quotes)",
                MAX_JSON_STRINGS)
    values = data.count(b",") + data.count(b":") + containers + 1
    check_count(file.path, values, "JSON values (counted by their separators)",
                MAX_JSON_VALUES)


def _uncertainty(reader: _Reader, data: dict, brdf: np.ndarray) -> np.ndarray | None:
    """u per point in 1/sr: uBRDF's, else BRDF's one stated uncertainty, else None."""
    if "uBRDF" in data:
        variable = reader.table(data, "uBRDF", "data")
        u, unit = reader.numbers(variable, "data.uBRDF", len(brdf)), variable.get("unit")
    elif isinstance(data["BRDF"].get("uncertainty"), dict):
        stated = data["BRDF"]["uncertainty"]
        u = np.full(len(brdf), reader.number(stated, "value", "data.BRDF.uncertainty"))
        unit = stated.get("unit")
    else:
        return None
    if unit == "%":
        return u / 100.0 * np.abs(brdf)
    if unit not in ("1/sr", "sr^-1"):
        raise reader.error("data.uBRDF.unit", f'must be "1/sr", "sr^-1" or "%", got {unit!r}')
    return u


def _adhoc(reader: _Reader, adhoc: dict, n: int, out: BirdData) -> None:
    """gonio's ad-hoc variables into `out`: u_NAME, shared_error_J, valid, flags."""
    shared = []
    for name in adhoc:
        where = f"data.adhoc_variables.{name}"
        if name.startswith("u_"):
            out.components[name[2:]] = reader.numbers(reader.table(adhoc, name, ""), where, n)
        elif name.startswith(SHARED_PREFIX):
            shared.append(reader.numbers(reader.table(adhoc, name, ""), where, n))
        elif name == "valid":
            values = reader.values(reader.table(adhoc, name, ""), where, n)
            if not all(isinstance(v, bool) for v in values):
                raise reader.error(f"{where}.values", "must be true or false")
            out.valid = np.array(values, bool)
        elif name == "flags":
            out.flags = np.array([str(v) for v in
                                  reader.values(reader.table(adhoc, name, ""), where, n)])
    if shared:
        out.shared_rel = np.stack(shared, axis=1)


class _Reader:
    """Checked access to a BiRD document's parts; errors name the file and the field."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def error(self, where: str, message: str) -> CalibrationError:
        return CalibrationError(f"{self.path}: not a BiRD BRDF file: {where}: {message}")

    def table(self, parent: Any, key: str, where: str) -> dict:
        """parent[key], which must be an object."""
        value = parent.get(key) if isinstance(parent, dict) else None
        if not isinstance(value, dict):
            raise self.error(f"{where}.{key}".lstrip("."), "missing, or not an object")
        return value

    def values(self, variable: dict, where: str, n: int | None = None) -> list:
        """variable["values"], a list (of n entries when n is given)."""
        values = variable.get("values")
        if not isinstance(values, list):
            raise self.error(f"{where}.values", "missing, or not a list")
        check_count(self.path, len(values), f"values of {where}", MAX_POINTS)
        if n is not None and len(values) != n:
            raise self.error(f"{where}.values", f"{len(values)} values for {n} BRDF values")
        return values

    def numbers(self, variable: dict, where: str, n: int | None = None) -> np.ndarray:
        """variable["values"] as float64, each a finite number."""
        values = self.values(variable, where, n)
        bad = next((k for k, v in enumerate(values) if isinstance(v, bool)
                    or not isinstance(v, (int, float)) or not math.isfinite(v)), None)
        if bad is not None:
            raise self.error(f"{where}.values[{bad}]", f"not a number: {values[bad]!r}")
        return np.array(values, dtype=np.float64)

    def number(self, table: dict, key: str, where: str) -> float:
        """table[key], a finite number."""
        value = table.get(key)
        if isinstance(value, bool) or not isinstance(value, (int, float)) \
                or not math.isfinite(value):
            raise self.error(f"{where}.{key}", f"not a number: {value!r}")
        return float(value)
