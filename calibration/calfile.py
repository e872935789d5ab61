"""Calibration files (JSON written, JSON or TOML read): date, source runs, values with
uncertainties; applying one to raw readings; and how a run records the calibration it used.

A run records its calibration in meta.json as
`"calibration": {"file": <absolute path>, "sha256": <hex>, "created_utc": <file's date>}`;
`used_by(run)` loads it back and refuses a file that changed since it was recorded.
"""

from __future__ import annotations

import hashlib
import json
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from calibration.detector import correct_power
from calibration.reference import ReferenceScale
from calibration.values import CalibrationError, Measured
from drivers.user_file import SETTINGS_FILE_CAP, read_user_file, user_text

FORMAT = "gonio-calibration/1"


@dataclass
class Calibration:
    """What one calibration determined; every section is optional (None: not measured)."""

    created_utc: str
    source_runs: list[str] = field(default_factory=list)
    dark_offsets_w: dict[str, Measured] | None = None  # per range key ("1e-06")
    gains: dict[str, Measured] | None = None  # per range key, relative to gain_reference
    gain_reference: str | None = None
    linearity: dict[str, Any] | None = None
    sample_offset_deg: Measured | None = None  # true = reported + offset
    arm_offset_deg: Measured | None = None
    angle_fit: dict[str, Any] | None = None  # the reference sample's fit behind the offsets
    aperture_solid_angle_sr: Measured | None = None
    aperture_half_angle_deg: Measured | None = None
    aperture_method: str | None = None  # "geometry" | "beam-scan"
    beam: list[dict[str, Any]] | None = None  # per source run: its beam readings' summary
    reference: ReferenceScale | None = None  # a certified panel's run: the effective solid angle
    notes: list[str] = field(default_factory=list)  # what was not calibrated, bad fits

    def to_json(self) -> dict[str, Any]:
        """The file's content."""
        def values(d: dict[str, Measured] | None) -> Any:
            return None if d is None else {k: v.to_json() for k, v in d.items()}

        def value(v: Measured | None) -> Any:
            return None if v is None else v.to_json()

        return {
            "format": FORMAT, "created_utc": self.created_utc, "source_runs": self.source_runs,
            "detector": {"dark_offset_w": values(self.dark_offsets_w),
                         "gain": values(self.gains), "gain_reference_range_w":
                             self.gain_reference, "linearity": self.linearity},
            "angles": {"sample_offset_deg": value(self.sample_offset_deg),
                       "arm_offset_deg": value(self.arm_offset_deg),
                       "fit": self.angle_fit},
            "aperture": {"solid_angle_sr": value(self.aperture_solid_angle_sr),
                         "half_angle_deg": value(self.aperture_half_angle_deg),
                         "method": self.aperture_method},
            "beam": self.beam,
            "reference": None if self.reference is None else self.reference.to_json(),
            "notes": self.notes,
        }

    @classmethod
    def from_json(cls, data: dict[str, Any], where: str) -> Calibration:
        """Parse a file's content; a CalibrationError names the file and the field."""
        if not isinstance(data, dict) or data.get("format") != FORMAT:
            raise CalibrationError(f"{where}: not a gonio calibration file (format must be "
                                   f"{FORMAT!r})")

        def table(name: str) -> dict[str, Any]:
            t = data.get(name) or {}
            if not isinstance(t, dict):
                raise CalibrationError(f"{where}: [{name}]: must be a table")
            return t

        def values(t: dict[str, Any], key: str, section: str) -> Any:
            d = t.get(key)
            if d is None:
                return None
            if not isinstance(d, dict):
                raise CalibrationError(f"{where}: [{section}] {key}: must be a table")
            return {k: Measured.from_json(v, f"{where}: [{section}.{key}] {k}")
                    for k, v in d.items()}

        def value(t: dict[str, Any], key: str, section: str) -> Measured | None:
            v = t.get(key)
            return None if v is None else Measured.from_json(v, f"{where}: [{section}] {key}")

        det, ang, ap = table("detector"), table("angles"), table("aperture")
        return cls(
            created_utc=str(data.get("created_utc", "")),
            source_runs=[str(r) for r in data.get("source_runs", [])],
            dark_offsets_w=values(det, "dark_offset_w", "detector"),
            gains=values(det, "gain", "detector"),
            gain_reference=det.get("gain_reference_range_w"),
            linearity=det.get("linearity"),
            sample_offset_deg=value(ang, "sample_offset_deg", "angles"),
            arm_offset_deg=value(ang, "arm_offset_deg", "angles"),
            angle_fit=ang.get("fit"),
            aperture_solid_angle_sr=value(ap, "solid_angle_sr", "aperture"),
            aperture_half_angle_deg=value(ap, "half_angle_deg", "aperture"),
            aperture_method=ap.get("method"),
            beam=data.get("beam"),
            reference=(None if data.get("reference") is None
                       else ReferenceScale.from_json(data["reference"], where)),
            notes=[str(n) for n in data.get("notes", [])],
        )


def save(cal: Calibration, path: str | Path) -> Path:
    """Write the calibration as JSON; returns the path."""
    path = Path(path)
    path.write_text(json.dumps(cal.to_json(), indent=2) + "\n")
    return path


def load(path: str | Path) -> Calibration:
    """Read a calibration file (.json, or .toml with the same structure)."""
    path = Path(path)
    return _parsed(path, _read(path))


def reference(path: str | Path) -> dict[str, str]:
    """What a run's meta.json records about the calibration file it used."""
    path = Path(path).resolve()
    data = _read(path)
    return {"file": str(path), "sha256": hashlib.sha256(data).hexdigest(),
            "created_utc": _parsed(path, data).created_utc}


def used_by(meta: dict[str, Any]) -> Calibration | None:
    """The calibration a run's meta records (None if none), checked against its hash: the
    bytes hashed are the bytes parsed."""
    ref = meta.get("calibration")
    if not ref:
        return None
    path = Path(ref["file"])
    if not path.exists():
        raise CalibrationError(f"the run's calibration file {path} is missing")
    data = _read(path)
    if hashlib.sha256(data).hexdigest() != ref.get("sha256"):
        raise CalibrationError(f"the run's calibration file {path} changed after the run "
                               "recorded it (sha256 differs)")
    return _parsed(path, data)


def _read(path: Path) -> bytes:
    """A calibration file's contents, read bounded (drivers.user_file)."""
    return read_user_file(path, "calibration file", SETTINGS_FILE_CAP, CalibrationError)


def _parsed(path: Path, data: bytes) -> Calibration:
    """The calibration the contents `data` of the file `path` hold (JSON, or TOML by suffix)."""
    text = user_text(data, path, "calibration file", CalibrationError)
    try:
        parsed = tomllib.loads(text) if path.suffix == ".toml" else json.loads(text)
    except (ValueError, tomllib.TOMLDecodeError) as exc:
        raise CalibrationError(f"{path}: not valid {path.suffix[1:] or 'JSON'}: {exc}") from exc
    return Calibration.from_json(parsed, str(path))


def apply(readings: np.ndarray, cal: Calibration) -> np.ndarray:
    """Calibrated copy of raw readings: power corrected for dark offset and range gain, stage
    angles corrected by the zero offsets and the sample-frame angles recomputed from them."""
    from gonio.geometry import sample_angles

    out = readings.copy()
    if cal.dark_offsets_w is not None:
        out["power_w"] = correct_power(readings["power_w"], readings["range_w"],
                                       cal.dark_offsets_w, cal.gains)
    if cal.sample_offset_deg is not None or cal.arm_offset_deg is not None:
        if cal.sample_offset_deg is not None:
            out["sample_deg"] += cal.sample_offset_deg.value
        if cal.arm_offset_deg is not None:
            out["arm_deg"] += cal.arm_offset_deg.value
        angles = sample_angles(out["sample_deg"], out["arm_deg"], out["elevation_deg"],
                               out["azimuth_deg"])
        for name in angles._fields:
            out[name] = getattr(angles, name)
    return out
