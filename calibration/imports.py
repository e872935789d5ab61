"""Measured BSDF files that gonio did not make, read into the ReducedData that `fit` and
`reduce` use: ASTM E1392 (`.astm`), Zemax tabular BSDF (`.bsdf`, `.zmx`, `.txt` with its
keywords), a BiRD universal BRDF file (`.json`), gonio's reduced NetCDF (`.nc`) and CSV, or a
plain CSV with named columns (theta_i, phi_i, theta_o, phi_o in degrees, with or without
`_deg`, theta_o above 90 for transmission; bsdf; optional sigma and wavelength_nm).
calibration.formats names the reader of each format and tells which format a file is.

Uncertainties come from the file where it has them (CSV `sigma`, NetCDF, BiRD uBRDF);
otherwise from a stated assumption (`sigma_relative`: u = that fraction of |bsdf|, put into
meta["noise_model"]), and the index from the file (the `# eta: ...` line of gonio's CSV, ASTM
and Zemax exports, else their record's sample block; the NetCDF's attributes; the BiRD file's
adhoc_section) or from `eta`. Every input a file lacks and no option gives is named in one error
(MissingInputs). The run's record that gonio's files carry (`# key: JSON` lines before the
facts' `quantity`; the NetCDF's record attributes; the BiRD adhoc_section) goes into
meta["record"], so that a file written from the import carries it on.
"""

from __future__ import annotations

import array
import csv
import itertools
import json
import math
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from calibration.exports.measured import ANGLE_COLUMNS, META_KEYS, unit_vectors
from calibration.formats import format_to_read
from calibration.formats.file_format import ImportOptions
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

# the column names of reduced.csv as `gonio reduce` wrote it before it used write_reduced_csv,
# and a plain table's `value`
ALIASES = {"bsdf_per_sr": "bsdf", "sigma_per_sr": "sigma", "value": "bsdf"}
# the columns a CSV must have, by their bare names
NEEDED = (*(a[:-4] for a in ANGLE_COLUMNS), "bsdf")
# the columns a table of one incidence must have (theta_i from the option or a header line)
SINGLE = ("theta_o", "bsdf")
# the header line (`# theta_i_deg: 30`) giving a table of one incidence its theta_i
INCIDENCE_KEY = "theta_i_deg"


class MissingInputs(CalibrationError):
    """Inputs a file lacks and no option gives, all of them in one error."""

    def __init__(self, path: Path, problems: list[str]) -> None:
        self.path, self.problems = path, problems
        listed = (problems[0] if len(problems) == 1 else f"{len(problems)} inputs missing: "
                  + "; ".join(f"({n}) {p}" for n, p in enumerate(problems, 1)))
        super().__init__(f"{path}: {listed}")


def read_measured(path: str | Path, options: ImportOptions | None = None) -> ReducedData:
    """The file's measurements as ReducedData, read as the format calibration.formats.
    format_to_read tells (its magic, its suffix, or for a text file of another suffix its first
    keyword); a MissingInputs error names every input the file lacks."""
    file = measured_file(path)  # read once: the format is told from these bytes, read from them
    data = format_to_read(file).read(file, options or ImportOptions())
    data.meta["imported_from"] = str(file.path)
    return data


def from_netcdf(file: MeasuredFile, options: ImportOptions) -> ReducedData:
    """gonio's reduced NetCDF file (calibration.exports.cf), with the uncertainties it states."""
    from calibration.exports.cf import read_reduced_netcdf

    data = read_reduced_netcdf(file)
    data.meta["eta"] = _inputs(file.path, options, data.meta, "the NetCDF file", True)
    data.meta.setdefault("assumption", "uncertainties as the file states them")
    return data


def _inputs(path: Path, options: ImportOptions, meta: dict, what: str,
            has_sigma: bool) -> float:
    """The index to use (the option's, else the file's); one MissingInputs error naming each
    input the file lacks that no option gives (or an option's value out of range)."""
    problems = []
    relative = options.sigma_relative
    if not has_sigma and relative is None:
        problems.append(f"{what} has no uncertainties, which the fit needs: give "
                        "--sigma-relative FRACTION to assume u = FRACTION * |bsdf|")
    elif not has_sigma and not 0.0 < relative < 10.0:
        problems.append(f"--sigma-relative must be in (0, 10), got {relative!r}")
    eta = options.eta if options.eta is not None else meta.get("eta")
    if eta is None:
        problems.append("the file gives no refractive index (eta), which the fit needs for a "
                        "dielectric: give --eta")
    elif not (isinstance(eta, (int, float)) and math.isfinite(eta) and eta > 0):
        problems.append(f"eta must be a number > 0, got {eta!r}")
    if problems:
        raise MissingInputs(path, problems)
    return float(eta)


def _assumed_sigma(bsdf: np.ndarray, relative: float) -> tuple[np.ndarray, str]:
    """(sigma, the assumption stated) for a file without uncertainties (_inputs checked
    `relative`)."""
    return relative * np.abs(bsdf), (
        f"assumed: u = {relative:g} * |bsdf| (the file states no uncertainties; "
        "--sigma-relative); values of 0 get no u from it and are left out (flag 'zero')")


def _reduced(path: Path, wi: np.ndarray, wo: np.ndarray, bsdf: np.ndarray,
             sigma: np.ndarray | None, transmission: np.ndarray, meta: dict,
             options: ImportOptions) -> ReducedData:
    """ReducedData of imported samples (meta["eta"] set by _inputs); the noise model says
    where sigma comes from."""
    if sigma is None:
        sigma, meta["noise_model"] = _assumed_sigma(bsdf, options.sigma_relative)
        meta["assumption"] = meta["noise_model"]
    else:
        meta.setdefault("noise_model", f"as stated in {path.name}")
    finite = np.isfinite(bsdf) & np.isfinite(sigma) & (sigma > 0)
    valid = meta.pop("valid", np.ones(len(bsdf), bool)) & finite
    flags = meta.pop("flags", None)
    zero = np.isfinite(bsdf) & (bsdf == 0) & ~(sigma > 0)
    if zero.any():  # a relative u of 0 would weigh the point infinitely: it is left out
        flags = np.array([""] * len(bsdf), dtype=object) if flags is None else flags.copy()
        flags[zero] = ["zero" if not f else f"{f},zero" for f in flags[zero]]
    components = meta.pop("components", {})
    return ReducedData(wi, wo, bsdf, sigma, valid, transmission, meta, flags=flags,
                       components=components)


def _header(comments: list[str]) -> tuple[dict, dict]:
    """(record, facts) of the `key: JSON` comment lines of a gonio file (comment text without
    its `#`; other lines are left out): the record is what comes before the facts' first line,
    `quantity` (measured.fact_lines); a file without one gives every entry as a fact and those
    that are not META_KEYS as its record."""
    entries = []
    for line in comments:
        key, sep, value = line.strip().partition(": ")
        if sep:
            try:
                entries.append((key, json.loads(value)))
            except ValueError:
                continue
    keys = [key for key, _ in entries]
    if "quantity" in keys:
        start = keys.index("quantity")
        return dict(entries[:start]), dict(entries[start:])
    return {k: v for k, v in entries if k not in META_KEYS}, dict(entries)


def _facts(path: Path, options: ImportOptions, comments: list[str], what: str,
           has_sigma: bool) -> dict:
    """The meta of a text file's comments (_header's record and facts, _meta)."""
    record, facts = _header(comments)
    return _meta(path, options, record, facts, what, has_sigma)


def _meta(path: Path, options: ImportOptions, record: dict, facts: dict, what: str,
          has_sigma: bool) -> dict:
    """The meta of a gonio file's record and facts: its facts (META_KEYS, from the record where
    the facts lack one, e.g. its sample block), the index (the option's, else the `eta` fact,
    else the sample block's: _inputs) and meta["record"]."""
    meta = {k: v for k, v in {**record, **facts}.items() if k in META_KEYS}
    sample = record.get("sample")
    if "eta" not in meta and isinstance(sample, dict) and "eta" in sample:
        meta["eta"] = sample["eta"]
    meta["eta"] = _inputs(path, options, meta, what, has_sigma)
    if record:
        meta["record"] = record
    return meta


def from_csv(file: MeasuredFile, options: ImportOptions) -> ReducedData:
    """A plain or gonio CSV (see the module docstring), read one line at a time within
    calibration.formats.limits."""
    path = file.path
    comments: list[str] = []
    line_no = [0]  # the file's line the reader is at, for a csv.Error

    def data_lines() -> Iterator[str]:
        for line_no[0], line in text_lines(file):
            if line.startswith("#"):
                comments.append(line[1:])
            elif line.strip():
                yield line

    reader = csv.reader(data_lines())
    no_rows = CalibrationError(f"{path}: no data rows under a header of column names")
    try:
        header = next(reader, None)
        if header is None:
            raise no_rows
        names = [ALIASES.get(n.strip(), n.strip()) for n in header]
        index = _column_index(path, names)
        columns = {name: array.array("d") for name in index if _numeric(name)}
        flags: list[str] = []
        row_no = 0
        for row_no, row in enumerate(reader, 1):
            check_count(path, row_no, "data rows or more", MAX_POINTS)
            for name, values in columns.items():
                values.append(_cell(path, row, index[name], name, row_no))
            if "flags" in index:
                k = index["flags"]
                flags.append(row[k].replace(";", ",") if k < len(row) else "")
    except csv.Error as exc:
        raise CalibrationError(f"{path}:{line_no[0]}: not CSV ({exc})") from None
    if row_no == 0:
        raise no_rows
    meta = _facts(path, options, comments, "the CSV", "sigma" in index)

    def column(name: str) -> np.ndarray:
        return np.frombuffer(columns[name], dtype=np.float64)

    wi, wo = _directions(path, {n: column(n) for n in columns}, comments, options)
    bsdf = column("bsdf")
    sigma = column("sigma") if "sigma" in index else None
    if "wavelength_nm" in index:
        wavelengths = np.unique(column("wavelength_nm"))
        if len(wavelengths) == 1 and np.isfinite(wavelengths[0]):
            meta["wavelength_nm"] = float(wavelengths[0])
    if "valid" in index:
        meta["valid"] = column("valid") != 0
    if "flags" in index:
        meta["flags"] = np.array(flags)
    meta["components"] = {n[2:]: column(n) for n in names if n.startswith("u_")}
    return _reduced(path, wi, wo, bsdf, sigma, wo[:, 2] < 0, meta, options)


def _column_index(path: Path, names: list[str]) -> dict[str, int]:
    """Each column name's first position (a `_deg` name also under its bare name); one error
    for too many columns or a needed one missing (a table without theta_i is one of a single
    incidence, which needs theta_o and bsdf only)."""
    check_count(path, len(names), "columns", MAX_COLUMNS)
    index: dict[str, int] = {}
    for k, name in enumerate(names):
        index.setdefault(name, k)
        if name.endswith("_deg"):
            index.setdefault(name[:-4], k)
    missing = [n for n in (NEEDED if "theta_i" in index else SINGLE) if n not in index]
    if missing:
        raise CalibrationError(f"{path}: no column {', '.join(missing)} (columns: theta_i_deg, "
                               "phi_i_deg, theta_o_deg, phi_o_deg, bsdf, optional sigma, "
                               "wavelength_nm; or, for one incidence, theta_o_deg[, phi_o_deg], "
                               "value[, sigma])")
    return index


def _directions(path: Path, columns: dict[str, np.ndarray], comments: list[str],
                options: ImportOptions) -> tuple[np.ndarray, np.ndarray]:
    """(wi, wo) of a CSV's rows. A table without theta_i is one of a single incidence: theta_i
    from ImportOptions.incidence_deg or the header line `# theta_i_deg: DEG`, phi_i 0, and
    without phi_o, theta_o the signed in-plane angle, positive on the specular side (away from
    the source) and within (-90, 90): one error for an incidence missing, given twice or out
    of range, or such a theta_o out of range."""
    if "theta_i" in columns:
        if options.incidence_deg is not None:
            raise CalibrationError(f"{path}: the table has a theta_i column; --incidence-deg is "
                                   "for a table of one incidence without one")
        return (unit_vectors(columns["theta_i"], columns["phi_i"]),
                unit_vectors(columns["theta_o"], columns["phi_o"]))
    stated = _header(comments)[1].get(INCIDENCE_KEY)
    if options.incidence_deg is not None and stated is not None:
        raise CalibrationError(f"{path}: the incidence is given twice (--incidence-deg and the "
                               f"header line `# {INCIDENCE_KEY}: {stated}`); give one")
    theta_i = options.incidence_deg if options.incidence_deg is not None else stated
    if theta_i is None:
        raise CalibrationError(f"{path}: a table without a theta_i column is one of a single "
                               "incidence: give --incidence-deg DEG or a header line "
                               f"`# {INCIDENCE_KEY}: DEG`")
    if isinstance(theta_i, bool) or not isinstance(theta_i, (int, float)) \
            or not 0.0 <= theta_i < 90.0:
        raise CalibrationError(f"{path}: the incidence must be a number of degrees in [0, 90), "
                               f"got {theta_i!r}")
    theta_o = columns["theta_o"]
    if "phi_o" in columns:
        phi_o = columns["phi_o"]
    else:
        if not np.all(np.abs(theta_o) < 90.0):
            raise CalibrationError(f"{path}: theta_o without a phi_o column is the signed "
                                   "in-plane angle and must lie within (-90, 90)")
        phi_o = np.where(theta_o >= 0.0, 180.0, 0.0)
        theta_o = np.abs(theta_o)
    n = len(theta_o)
    return unit_vectors(np.full(n, float(theta_i)), np.zeros(n)), unit_vectors(theta_o, phi_o)


def _numeric(name: str) -> bool:
    """True for a column read as numbers (every column the import uses but `flags`)."""
    return name in (*NEEDED, "sigma", "wavelength_nm", "valid") or name.startswith("u_")


def _cell(path: Path, row: list[str], k: int, name: str, row_no: int) -> float:
    """The number in column k of a data row (NaN where empty); one error if it is not one."""
    text = row[k] if k < len(row) else None
    if text is not None and not text.strip():
        return math.nan
    try:
        return float(text)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise CalibrationError(f"{path}: data row {row_no}: column {name} is not a "
                               "number") from None


def from_astm(file: MeasuredFile, options: ImportOptions) -> ReducedData:
    """An ASTM E1392 file: its first value column (one wavelength)."""
    from calibration.exports.astm import directions, read_astm

    path, table = file.path, read_astm(file)
    if table.values.shape[1] != 1:
        raise CalibrationError(f"{path}: {table.values.shape[1]} value columns (one per "
                               "wavelength); the fit takes one wavelength: split the file")
    meta = _facts(path, options, table.comments, "an ASTM E1392 file", False)
    wi, wo, transmission = directions(table)
    if math.isfinite(table.wavelengths_nm[0]):
        meta["wavelength_nm"] = table.wavelengths_nm[0]
    return _reduced(path, wi, wo, table.values[:, 0], None, transmission, meta, options)


def from_zemax(file: MeasuredFile, options: ImportOptions) -> ReducedData:
    """A Zemax tabular BSDF file: every grid value on its side's hemisphere (the file does
    not say which are measured, so the fit takes all of them), at its incidence angles
    (BTDF: recovered from the direct-transmission angle with `eta`)."""
    from calibration.exports.zemax import on_side, read_zemax, scatter_directions, turned

    path, table = file.path, read_zemax(file)
    meta = _facts(path, options, table.comments, "a Zemax tabular BSDF file", False)
    eta = meta["eta"]
    wi, wo, bsdf = [], [], []
    for (r, rotation), (a, angle) in itertools.product(enumerate(table.sample_rotation_deg),
                                                       enumerate(table.angle_deg)):
        if r and angle == 0.0:  # normal incidence: every rotation holds the same points
            continue
        theta_i = (angle if table.scatter_type == "BRDF" else
                   math.degrees(math.asin(min(1.0, eta * math.sin(math.radians(angle))))))
        directions = scatter_directions(angle, table.scatter_type, table.azimuth_deg,
                                        table.radial_deg)
        keep = on_side(directions, table.scatter_type)
        keep &= np.abs(directions[..., 2]) > 1e-9
        keep[1:, table.radial_deg == 0.0] = False  # the specular direction, once
        keep[table.azimuth_deg >= 360.0] = False  # a closing row repeats azimuth 0
        if table.symmetry == "PlaneSymmetrical":
            inside = (table.azimuth_deg > 0) & (table.azimuth_deg < 180)
            mirrored = directions[inside] * np.array([1.0, -1.0, 1.0])
            directions = np.concatenate([directions, mirrored])
            values = np.concatenate([table.data[r, a], table.data[r, a][inside]])
            keep = np.concatenate([keep, keep[inside]])
        else:
            values = table.data[r, a]
        ti = math.radians(theta_i)
        wo.append(turned(directions[keep], -rotation))  # the sample turned by `rotation`
        bsdf.append(values[keep])
        wi.append(np.broadcast_to(turned(np.array([-math.sin(ti), 0.0, math.cos(ti)]), -rotation),
                                  (int(keep.sum()), 3)))
    wo_all = np.concatenate(wo)
    return _reduced(path, np.concatenate(wi), wo_all, np.concatenate(bsdf), None,
                    wo_all[:, 2] < 0, meta, options)


def from_bird(file: MeasuredFile, options: ImportOptions) -> ReducedData:
    """A BiRD universal BRDF file (calibration.exports.bird_read): its points on the reflection
    side, with gonio's budget, shared errors, validity, flags, facts and record where the file
    carries them (a file gonio wrote)."""
    from calibration.exports.bird_read import read_bird

    path, bird = file.path, read_bird(file)
    meta = _meta(path, options, bird.record, bird.facts, "the BiRD file", bird.sigma is not None)
    if bird.wavelength_nm is not None:
        meta["wavelength_nm"] = bird.wavelength_nm
    if bird.valid is not None:
        meta["valid"] = bird.valid
    if bird.flags is not None:
        meta["flags"] = bird.flags
    meta["components"] = bird.components
    angles = bird.angles_deg
    wi = unit_vectors(angles["theta_i"], angles["phi_i"])
    wo = unit_vectors(angles["theta_r"], angles["phi_r"])
    data = _reduced(path, wi, wo, bird.brdf, bird.sigma, np.zeros(len(wo), bool), meta, options)
    if bird.shared_rel is not None:
        data.shared_rel = bird.shared_rel
    return data
