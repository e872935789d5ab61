"""The `metadata` section of a BiRD universal BRDF file, built from a run's record
(gonio.record.run_record): who measured (config [provenance]), when, the instrument (config
[optics]: source, beam, receiver aperture, detector range; the detector as it reported itself),
the sample (plan [sample]: shape, dimensions, azimuth reference) and the room (plan
[environment]). Every field the BiRD schema requires comes from the record; where the record
lacks one, `bird_metadata` refuses with one line naming each plan or config key to add (or to
give at export time: calibration.exports.bird_supplement, whose file the provenance comments
then name).
"""

from __future__ import annotations

import importlib.metadata
import math
import uuid
from collections.abc import Mapping
from typing import Any

from calibration.exports.bird_supplement import supplement_sentence
from calibration.values import CalibrationError

SCHEMA_BASE = "https://raw.githubusercontent.com/BiRD-project/BiRD_view/master/BRDF_JSON_schema/"
SCHEMA_URL = f"{SCHEMA_BASE}brdf_json_schema_v1.0.json"
#: The keys of config [provenance] the BiRD provenance and licence need.
PROVENANCE_KEYS = ("lab", "contact", "email", "street", "building", "postal_code", "city",
                   "country", "licence")
#: The record's keys from config [optics] the instrument section needs: (record key, the
#: [optics] key to name when it is missing).
OPTICS_KEYS = (("wavelength_nm", "wavelength_nm"), ("beam_diameter_mm", "beam_diameter_mm"),
               ("receiver_solid_angle_sr", "aperture_diameter_mm"),
               ("detector_spectral_range_nm", "detector_spectral_range_nm"))
SOURCE_KEYS = ("source_name", "source_type", "source_power_mw")
#: gonio's polarisation states as BiRD's sp notation.
SP_NOTATION = {"unpolarised": "u", "s": "s", "p": "p"}


def missing_keys(record: Mapping[str, Any]) -> list[tuple[str, str]]:
    """The plan and config keys the record lacks that a BiRD file requires, as (where, key):
    ("config [optics]", "source_power_mw"); empty: none."""
    missing = [("config", key) for name, key in (("instrument", "name"),
                                                 ("detector", "[detector] device"))
               if not record.get(name)]
    provenance = record.get("provenance") or {}
    missing += [("config [provenance]", k) for k in PROVENANCE_KEYS if not provenance.get(k)]
    source = record.get("light_source") or {}
    missing += [("config [optics]", k) for k in SOURCE_KEYS if source.get(k) in (None, "")]
    missing += [("config [optics]", key) for name, key in OPTICS_KEYS if record.get(name) is None]
    sample = record.get("sample")
    if not sample:
        missing.append(("plan [sample]", "id, kind, eta, shape, diameter_mm, azimuth_reference"))
    else:
        missing += [("plan [sample]", k) for k in ("shape", "azimuth_reference")
                    if not sample.get(k)]
        if not _dimensions(sample):
            missing.append(("plan [sample]", "diameter_mm (or length_mm and width_mm)"))
    if (record.get("environment") or {}).get("temperature_c") is None:
        missing.append(("plan [environment]", "temperature_c (or a config environment sensor)"))
    if not record.get("started_utc"):
        missing.append(("the run's meta.json", "started_utc"))
    return missing


def missing_text(missing: list[tuple[str, str]]) -> str:
    """The missing keys grouped by where they go: `config [optics] source_name, source_type;
    plan [environment] temperature_c`."""
    grouped: dict[str, list[str]] = {}
    for where, key in missing:
        grouped.setdefault(where, []).append(key)
    return "; ".join(f"{where} {', '.join(keys)}" for where, keys in grouped.items())


def require_complete(record: Mapping[str, Any]) -> None:
    """A CalibrationError naming every key the record lacks (missing_keys), if any."""
    missing = missing_keys(record)
    if missing:
        raise CalibrationError("export: --format bird needs what the run's record lacks: "
                               + missing_text(missing)
                               + "; --provenance FILE.toml gives them at export time")


def bird_metadata(record: Mapping[str, Any], description: str, comments: str) -> dict[str, Any]:
    """The metadata section of a measured BRDF data set (see the module docstring); a
    CalibrationError naming every missing key (missing_keys) when the record lacks any."""
    require_complete(record)
    meta = {
        "schema": SCHEMA_URL, "id": dataset_id(record), "type": "BRDF",
        "timestamp": record["started_utc"], "provenance": provenance(record["provenance"]),
        "license": licence(record["provenance"]), "description": description,
        "method": "measurement", "instrumentation": instrumentation(record),
        "software": software(), "sample": sample(record["sample"]),
        "environment": environment(record["environment"]), "comments": comments,
    }
    given = supplement_sentence(record)
    if given:
        meta["provenance"]["comments"] = given
        meta["comments"] = f"{comments} {given}"
    return meta


def dataset_id(record: Mapping[str, Any]) -> str:
    """A URN naming the data set: the same run (instrument, run directory, start) gives the
    same one, any other run another."""
    key = f"gonio:{record.get('instrument')}:{record.get('run')}:{record['started_utc']}"
    return f"urn:uuid:{uuid.uuid5(uuid.NAMESPACE_URL, key)}"


def provenance(p: Mapping[str, Any]) -> dict[str, Any]:
    """BiRD provenance of config [provenance]."""
    out = {"organization": p["lab"], "location": {
        "country": p["country"], "city": p["city"], "street": p["street"],
        "building_nr": p["building"], "postal_code": p["postal_code"]},
        "email": p["email"], "contact_person": p["contact"]}
    if p.get("phone"):
        out["phone"] = p["phone"]
    return out


def licence(p: Mapping[str, Any]) -> dict[str, Any]:
    """BiRD license of config [provenance] (the holder: the lab unless it names another)."""
    out = {"type": p["licence"], "rights_holder": p.get("licence_holder") or p["lab"]}
    if p.get("licence_url"):
        out["link"] = p["licence_url"]
    return out


def _quantity(value: float, unit: str, u: float | None = None) -> dict[str, Any]:
    """A BiRD {value, unit} with its standard uncertainty in the same unit where known."""
    out: dict[str, Any] = {"value": float(value), "unit": unit}
    if u is not None:
        out.update(uncertainty=float(u), uncertainty_unit=unit)
    return out


def _circle(diameter_mm: float) -> dict[str, Any]:
    """BiRD dimensions of a circle of this diameter (with its area, which BiRD requires)."""
    return {"diameter": _quantity(diameter_mm, "mm"),
            "area": _quantity(math.pi * diameter_mm**2 / 4.0, "mm^2")}


def instrumentation(record: Mapping[str, Any]) -> dict[str, Any]:
    """The instrument: its source and beam, the receiver and the detector as reported."""
    source = record["light_source"]
    power = _quantity(source["source_power_mw"], "mW", source.get("u_source_power_mw"))
    source_out = {"name": source["source_name"], "type": source["source_type"],
                  "power": power, "central_wl": _quantity(record["wavelength_nm"], "nm")}
    if record.get("bandwidth_nm") is not None:
        source_out["comments"] = f"bandwidth (FWHM) {record['bandwidth_nm']:g} nm"
    beam = {"shape": "circular", "dimensions": _circle(record["beam_diameter_mm"])}
    if record.get("beam_divergence_half_angle_deg") is not None:
        beam["divergence"] = _quantity(record["beam_divergence_half_angle_deg"], "deg")
        beam["comments"] = "divergence: the beam's half-angle"
    low, high = record["detector_spectral_range_nm"]
    name, identity = detector(record)
    sensor = {"name": identity.get("sensor_name") or name,
              "spectral_response_range": {"min_value": low, "max_value": high, "unit": "nm"}}
    if identity.get("sensor_serial"):
        sensor["model"] = f"{sensor['name']} serial {identity['sensor_serial']}"
    detection = {"name": name, "sensors": [sensor],
                 "solid_angle": _quantity(record["receiver_solid_angle_sr"], "sr")}
    if identity.get("idn"):
        detection["model"] = identity["idn"]
    if record.get("aperture_diameter_mm") is not None:
        detection["aperture"] = {"name": "receiver aperture", "shape": "circular",
                                 "dimensions": _circle(record["aperture_diameter_mm"])}
        detection["distance_from_sample"] = _quantity(record["aperture_distance_mm"], "mm")
    out = {"name": record["instrument"],
           "operation_type": "absolute",
           "illumination_system": {"name": source["source_name"], "source": source_out,
                                   "beam": beam},
           "detection_system": detection,
           "comments": "absolute: the incident power is measured by beam readings"}
    operator = (record.get("sample") or {}).get("operator")
    if operator:
        out["operator_name"] = operator
    return out


def detector(record: Mapping[str, Any]) -> tuple[str, dict[str, Any]]:
    """(name, identity as it reported itself in the run's last session) of the config's
    detector device ({} where no session recorded its identity)."""
    name = record["detector"]
    devices = ((record.get("sessions") or [{}])[-1].get("devices") or {})
    return name, (devices.get(name) or {}).get("identity") or {}


def software() -> dict[str, Any]:
    """gonio, which reduced the data (with its version where it is installed)."""
    out = {"name": "gonio", "comments": "reduction of the raw readings to BRDF with the GUM "
                                        "uncertainty budget"}
    try:
        out["version"] = importlib.metadata.version("gonio")
    except importlib.metadata.PackageNotFoundError:
        pass
    return out


def sample(s: Mapping[str, Any]) -> dict[str, Any]:
    """BiRD sample of plan [sample]: id, kind, shape, dimensions, azimuth reference."""
    out = {"name": s["id"], "type": s["kind"], "shape": s["shape"],
           "dimensions": _dimensions(s), "zero_azimuth_location": s["azimuth_reference"]}
    if s.get("description"):
        out["comments"] = s["description"]
    return out


def _dimensions(s: Mapping[str, Any]) -> dict[str, Any]:
    """The sample's stated dimensions in BiRD's terms, with the area a disc or a rectangle
    has; {} when it states neither a diameter nor a length and width."""
    if s.get("diameter_mm") is not None:
        out = _circle(s["diameter_mm"])
    elif s.get("length_mm") is not None and s.get("width_mm") is not None:
        out = {"length": _quantity(s["length_mm"], "mm"), "width": _quantity(s["width_mm"], "mm"),
               "area": _quantity(s["length_mm"] * s["width_mm"], "mm^2")}
    else:
        return {}
    if s.get("thickness_mm") is not None:
        out["thickness"] = _quantity(s["thickness_mm"], "mm")
    return out


def environment(e: Mapping[str, Any]) -> dict[str, Any]:
    """BiRD environment of plan [environment] (relative humidity in %)."""
    out = {"temperature": _quantity(e["temperature_c"], "°C", e.get("u_temperature_c"))}
    if e.get("humidity_rel") is not None:
        u = e.get("u_humidity_rel")
        out["relative_humidity"] = _quantity(100.0 * e["humidity_rel"], "%",
                                             None if u is None else 100.0 * u)
    if e.get("notes"):
        out["comments"] = e["notes"]
    return out


def polarisation(state: Any) -> str | None:
    """A gonio polarisation in BiRD's sp notation; None for a linear polariser's angle, which
    sp cannot say."""
    return SP_NOTATION.get(state) if isinstance(state, str) else None
