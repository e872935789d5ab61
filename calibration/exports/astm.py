"""ASTM E1392 ASCII BSDF files (`.astm`, what libbsdf and BSDF Processor read): writer and
reader.

Layout, as libbsdf's AstmReader parses it: header lines of `KEYWORD value` (it skips every
token until `NUM_POINTS n` and `VARS ...`), then `VARS theta_i,phi_i,theta_s,phi_s,<values>`,
one value column per wavelength named like `632.8nm` (`value` where the wavelength is not
known: libbsdf reads it as monochrome), then one comma-separated line per
sample: the four angles in radians (theta from the normal of the side's hemisphere, phi in
[0, 2 pi)) and the BSDF in 1/sr. Angles are rounded in degrees (measured.ANGLE_DECIMALS) and
written as the exact double of that many degrees in radians, so that one angle is one text
(no second "180 deg" node a digit apart, no 2 pi beside 0). Every sample of an isotropic run
names the source azimuth of gonio's sample frame (phi_i = pi, the plane of incidence
x-z), normal incidence included (measured.file_angles_deg; an outgoing direction along the
normal has phi_s 0): libbsdf takes a file whose phi_i is one value for isotropic
and turns its phi_s by that value, and a file with two for anisotropic, filling the missing
incidence azimuths with the nearest sample. No comment may follow VARS (the reader takes every
later line as data). One file holds one side, as libbsdf reads a file as a BRDF or a BTDF: the gonio
writer names it in a `DATA_TYPE BRDF|BTDF` line (a file without one is read as a BRDF).
"""

from __future__ import annotations

import array
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from calibration.exports.measured import (
    SOURCE_AZIMUTH_DEG,
    file_angles_deg,
    rounded_deg,
    unit_vectors,
)
from calibration.formats.limits import (
    MAX_COLUMNS,
    MAX_POINTS,
    MeasuredFile,
    check_count,
    measured_file,
    text_lines,
)
from calibration.reduced import ReducedData
from calibration.values import CalibrationError

ANGLES = ("theta_i", "phi_i", "theta_s", "phi_s")
DATA_TYPES = ("BRDF", "BTDF")


@dataclass
class AstmTable:
    """One side's samples: angles (N,) in radians, values (N, n_wavelengths) in 1/sr."""

    data_type: str
    theta_i: np.ndarray
    phi_i: np.ndarray
    theta_s: np.ndarray  # from +z (BRDF) or -z (BTDF)
    phi_s: np.ndarray
    wavelengths_nm: list[float]
    values: np.ndarray
    header: dict[str, str] = field(default_factory=dict)  # other KEYWORD value lines
    comments: list[str] = field(default_factory=list)
    source: str = "MEASURED"  # or MODEL


def _comment(text: str) -> str:
    """A header comment no reader mistakes for a keyword (libbsdf reads VARS / NUM_POINTS
    wherever they stand as words)."""
    words = ["vars" if w == "VARS" else "num_points" if w == "NUM_POINTS" else w
             for w in text.split()]
    return "# " + " ".join(words)


def write_astm(table: AstmTable, path: str | Path) -> Path:
    """Write one side's samples as ASTM E1392 ASCII: angles by radians_text, values with
    every digit (repr)."""
    path = Path(path)
    if table.data_type not in DATA_TYPES:
        raise CalibrationError(f"astm: data type must be BRDF or BTDF, got {table.data_type!r}")
    names = [f"{w:g}nm" if math.isfinite(w) else "value" for w in table.wavelengths_nm]
    lines = [_comment(c) for c in table.comments]
    lines += [f"SOURCE {table.source}", f"DATA_TYPE {table.data_type}"]
    lines += [f"{key} {value}" for key, value in table.header.items()]
    lines += [f"NUM_POINTS {len(table.theta_i)}", "VARS " + ",".join([*ANGLES, *names])]
    angles = np.stack([radians_text(table.theta_i), radians_text(table.phi_i, True),
                       radians_text(table.theta_s), radians_text(table.phi_s, True)], axis=1)
    for a, v in zip(angles, np.atleast_2d(table.values.T).T, strict=True):
        lines.append(",".join([*a, *(repr(float(x)) for x in v)]))
    path.write_text("\n".join(lines) + "\n")
    return path


def radians_text(angle_rad: np.ndarray, azimuth: bool = False) -> list[str]:
    """Angles as text: rounded in degrees (measured.rounded_deg), written as the shortest repr
    of that many degrees in radians."""
    degrees = rounded_deg(np.degrees(np.asarray(angle_rad, dtype=np.float64)), azimuth)
    return [repr(float(r) + 0.0) for r in np.radians(degrees)]


def _wavelength(name: str) -> float:
    """The wavelength of a value column named like `632.8nm`; NaN for another name."""
    try:
        return float(name[:-2]) if name.endswith("nm") else math.nan
    except ValueError:
        return math.nan


def read_astm(source: str | Path | MeasuredFile) -> AstmTable:
    """Parse an ASTM E1392 file, one line at a time within calibration.formats.limits; an
    error names the line that is wrong."""
    file = measured_file(source)  # read once, within the limits
    path = file.path
    header: dict[str, str] = {}
    comments: list[str] = []
    names: list[str] | None = None
    values = array.array("d")
    rows = 0
    for n, line in text_lines(file):
        text = line.strip()
        if names is not None:
            if text:
                rows += 1
                check_count(path, rows, "data lines or more", MAX_POINTS)
                values.extend(_numbers(path, n, text, len(names)))
            continue
        if text.startswith("#"):
            comments.append(text[1:].strip())
            continue
        key, _, value = text.partition(" ")
        if key == "VARS":
            names = [v.strip() for v in value.split(",")]
            check_count(path, len(names), "columns", MAX_COLUMNS)
            if len(names) < 5:
                raise CalibrationError(f"{path}:{n}: VARS needs four angles and at least one "
                                       f"value column, has {len(names)}")
        elif key:
            header[key] = value.strip()
    if names is None:
        raise CalibrationError(f"{path}: no VARS line (ASTM E1392 names its columns in one)")
    if not rows:
        raise CalibrationError(f"{path}: no data line after VARS")
    data = np.frombuffer(values, dtype=np.float64).reshape(rows, len(names))
    data_type = header.pop("DATA_TYPE", "BRDF")
    source = header.pop("SOURCE", "MEASURED")
    if data_type not in DATA_TYPES:
        raise CalibrationError(f"{path}: DATA_TYPE must be BRDF or BTDF, got {data_type!r}")
    return AstmTable(data_type, data[:, 0], data[:, 1], data[:, 2], data[:, 3],
                     [_wavelength(nm) for nm in names[4:]], data[:, 4:], header, comments,
                     source)


def _numbers(path: Path, n: int, text: str, columns: int) -> list[float]:
    """The comma-separated numbers of data line n, as many as VARS names columns."""
    try:
        row = [float(v) for v in text.split(",")]
    except ValueError:
        raise CalibrationError(f"{path}:{n}: not comma-separated numbers: "
                               f"{text[:60]!r}") from None
    if len(row) != columns:
        raise CalibrationError(f"{path}:{n}: {columns} columns named in VARS, {len(row)} given")
    return row


def sides_of(transmission: np.ndarray) -> list[str]:
    """The data types measured, the BTDF first (the main file of a two-sided export)."""
    return [s for s, present in (("BTDF", transmission.any()), ("BRDF", (~transmission).any()))
            if present]


def side_paths(out_path: str | Path, sides: Sequence[str]) -> list[Path]:
    """One path per side: out_path for the first, <stem>-<SIDE><suffix> beside it for the
    rest (as the Zemax export names its second file)."""
    out_path = Path(out_path)
    return [out_path if k == 0 else out_path.with_name(f"{out_path.stem}-{side}"
                                                       f"{out_path.suffix}")
            for k, side in enumerate(sides)]


def astm_tables(data: ReducedData, comments: Sequence[str] = ()) -> list[AstmTable]:
    """The valid points of reduced data as one table per measured side (sides_of order)."""
    good = data.subset(data.valid)
    wavelength = good.meta.get("wavelength_nm")
    tables = []
    for side in sides_of(good.transmission):
        part = good.subset(good.transmission == (side == "BTDF"))
        ti, pi = file_angles_deg(part.wi, SOURCE_AZIMUTH_DEG)
        to, po = file_angles_deg(part.wo, 0.0)
        theta_s = 180.0 - to if side == "BTDF" else to
        tables.append(AstmTable(side, np.radians(ti), np.radians(pi), np.radians(theta_s),
                                np.radians(po), [math.nan if wavelength is None
                                                 else float(wavelength)],
                                part.bsdf[:, None], comments=list(comments)))
    return tables


def directions(table: AstmTable) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(wi, wo, transmission) of a table's samples in the sample frame."""
    wi = unit_vectors(np.degrees(table.theta_i), np.degrees(table.phi_i))
    wo = unit_vectors(np.degrees(table.theta_s), np.degrees(table.phi_s))
    transmission = np.full(len(wo), table.data_type == "BTDF")
    wo[transmission, 2] *= -1.0
    return wi, wo, transmission
