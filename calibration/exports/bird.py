"""Reduced BRDF as a BiRD universal BRDF file (the JSON format of the EMPIR BiRD project, which
metrology institutes exchange BRDF data in; schema v1.0): `metadata` from the run's record
(calibration.exports.bird_metadata) and `data` with one entry per reflection point: theta_i,
phi_i, theta_r, phi_r in degrees (sample frame; rounded, and along the normal phi_i the
source's azimuth and phi_r 0, as in the ASTM export: measured.file_angles_deg), BRDF and its
standard uncertainty uBRDF in 1/sr, the wavelength and, where sp notation says them, the
polarisations. What the format has
no field for goes in its ad-hoc variables, one value per point: each budget component
`u_NAME` (1/sr), each error the points share `shared_error_J` (relative), `valid` and `flags`;
the reduction's facts and the whole record go in metadata's adhoc_section, so that `--import`
gives the same data back (calibration.exports.bird_read).

BiRD holds a BRDF: transmission points, values below 0 (noise around a dark level) and points
without a finite value cannot be written, and are left out with a note saying how many.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from calibration.exports.bird_metadata import bird_metadata, polarisation, require_complete
from calibration.exports.measured import (
    SOURCE_AZIMUTH_DEG,
    coverage_k,
    file_angles_deg,
    meta_facts,
)
from calibration.reduced import ReducedData

#: metadata.adhoc_section's keys for the run's record and the reduction's facts.
RECORD_KEY, FACTS_KEY = "gonio_record", "gonio_facts"
SHARED_PREFIX = "shared_error_"
FRAME = ("Angles in degrees in the sample frame of gonio's docs/architecture.md: theta from the "
         "sample normal, phi from the frame's +x axis, the source at (theta_i, phi_i)")


def write_bird(data: ReducedData, out: Path, record: Mapping[str, Any]) -> tuple[Path, list[str]]:
    """Write the data's reflection points as a BiRD file; (the path, notes on what was left
    out). Refuses (CalibrationError, one line) before writing when the record lacks a field
    the format requires."""
    require_complete(record)
    keep, notes = writable(data)
    kept = data.subset(keep)
    comments = " ".join([f"{FRAME}.", "uBRDF is the standard uncertainty u (GUM); the "
                         f"expanded uncertainty is U = k u with k = {coverage_k(data):g}.",
                         *notes])
    document = {"metadata": bird_metadata(record, description(record), comments),
                "data": data_section(kept, record)}
    document["metadata"]["adhoc_section"] = {RECORD_KEY: dict(record),
                                             FACTS_KEY: meta_facts(data)}
    out.write_text(json.dumps(strict_json(document), indent=1, ensure_ascii=False) + "\n")
    return out, [f"bird: {note}" for note in notes]


def writable(data: ReducedData) -> tuple[np.ndarray, list[str]]:
    """(the points a BRDF file can hold: reflection, finite, >= 0, with a finite u >= 0;
    what is left out, as sentences)."""
    finite = np.isfinite(data.bsdf) & np.isfinite(data.sigma) & (data.sigma >= 0)
    reflection = ~data.transmission
    keep = reflection & finite & (data.bsdf >= 0)
    notes = []
    for count, what in ((int(np.sum(data.transmission)), "on the transmission side (BiRD "
                         "holds a BRDF; the CSV, NetCDF, ASTM and Zemax exports hold them)"),
                        (int(np.sum(reflection & ~finite)), "without a finite value or "
                         "uncertainty"),
                        (int(np.sum(reflection & finite & (data.bsdf < 0))),
                         "below 0 (BiRD's BRDF is >= 0)")):
        if count:
            notes.append(f"left out {count} point{'' if count == 1 else 's'} {what}.")
    return keep, notes


def description(record: Mapping[str, Any]) -> str:
    """One sentence on what the file holds."""
    sample = record.get("sample") or {}
    what = f" ({sample['description']})" if sample.get("description") else ""
    return (f"BRDF of sample {sample.get('id')}{what} at {record.get('wavelength_nm'):g} nm, "
            f"measured on the instrument {record.get('instrument')} (gonio run "
            f"{record.get('run')}).")


def _variable(values: np.ndarray | list, unit: str, **more: Any) -> dict[str, Any]:
    """A BiRD data variable: its unit, its values as a list, and `more`."""
    return {**more, "unit": unit,
            "values": values.tolist() if isinstance(values, np.ndarray) else values}


def data_section(data: ReducedData, record: Mapping[str, Any]) -> dict[str, Any]:
    """The data section of reflection points (see the module docstring)."""
    n = len(data.bsdf)
    theta_i, phi_i = file_angles_deg(data.wi, SOURCE_AZIMUTH_DEG)
    theta_r, phi_r = file_angles_deg(data.wo, 0.0)
    angles = {"theta_i": theta_i, "phi_i": phi_i, "theta_r": theta_r, "phi_r": phi_r}
    out = {name: _variable(values, "deg", name=name) for name, values in angles.items()}
    out["BRDF"] = _variable(data.bsdf, "1/sr", name="BRDF")
    out["uBRDF"] = _variable(data.sigma, "1/sr", comments="standard uncertainty u (GUM, k = 1)")
    if record.get("wavelength_nm") is not None:
        out["wavelength_i"] = _variable([float(record["wavelength_nm"])] * n, "nm",
                                        name="wavelength_i")
    for key, name in (("source_polarisation", "polarization_i"),
                      ("analyser_polarisation", "polarization_r")):
        state = polarisation(record.get(key))
        if state is not None:
            out[name] = {"name": name, "notation": "sp", "values": [state] * n}
    out["adhoc_variables"] = adhoc_variables(data)
    return out


def adhoc_variables(data: ReducedData) -> dict[str, Any]:
    """Per point: the budget's components, the shared errors, valid and flags."""
    out = {f"u_{name}": _variable(np.asarray(u, float), "1/sr", type="number",
                                  description=f"standard uncertainty component {name} of BRDF "
                                              "(GUM)")
           for name, u in data.components.items()}
    for j, column in enumerate(data.shared_rel.T, start=1):
        out[f"{SHARED_PREFIX}{j}"] = _variable(
            column, "1", type="number", description=f"shared error {j}: a relative error "
            "common to the points (the values carry shared_error_J z_J, z_J ~ N(0, 1)); uBRDF "
            "includes each point's part of it")
    out["valid"] = _variable(data.valid.astype(bool), "", type="boolean",
                             description="whether fits and plots use the point")
    out["flags"] = _variable([str(f) for f in data.flags], "", type="string",
                             description="why a point is suspect, comma-separated")
    return out


def strict_json(value: Any) -> Any:
    """`value` as strict JSON holds it: numpy scalars and arrays as Python's, non-finite
    numbers (which JSON has no word for) as null."""
    if isinstance(value, Mapping):
        return {str(k): strict_json(v) for k, v in value.items()}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [strict_json(v) for v in value]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value
