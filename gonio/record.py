"""The record of a run that every export carries, and the one gate to the emulator's truth.

`run_record(run)` assembles what the standards ask to go with the data (ASTM E2387, ISO 19986,
SEMI ME1392): wavelength and bandwidth, receiver solid angle, beam size and divergence,
polarisation states, the source, the sample block, the room's environment, who measured
(provenance), the calibration used and each device's identity per session. It is built from
meta.json (what the scan recorded), falling back on the stored config's [optics] and plan's
[sample] for runs older than those blocks; the environment comes from the readings' room
fields when the stored config has an environment sensor (gonio.room_sensor), else from the
stored plan's [environment]; the provenance from the stored config's [provenance].

`emulator_config(run)` is the only way reduction, fits and plots reach a run's [sim] table:
it gives it for a run whose devices were all emulated, and None for any other run.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from typing import Any

from gonio.completeness import completeness_of
from gonio.environment import Environment, environment_of_plan
from gonio.optics import optics_of_config
from gonio.provenance import provenance_of_config
from gonio.room_sensor import environment_of_lines, sensor_of_config
from gonio.sample import sample_of_plan
from gonio.store import Run

#: The [optics] keys that describe the source, the record's `light_source` block (`source`
#: is a CF global attribute of the NetCDF exports, which carry the record).
SOURCE_KEYS = ("source_name", "source_type", "source_power_mw", "u_source_power_mw")


def all_emulated(meta: Mapping[str, Any]) -> bool:
    """True when every device of every session was emulated (`gonio scan --sim`)."""
    if meta.get("sim") is not True:
        return False
    return all(set(s.get("endpoints", {})) <= set(s.get("sim", s.get("endpoints", {})))
               for s in meta.get("sessions", []))


def on_virtual_clock(meta: Mapping[str, Any]) -> bool:
    """True when a session of the run counted its readings' `t_s` on the emulated bench's
    virtual clock (session `clock` "virtual"): run time, not seconds since `t0_epoch`."""
    return any(s.get("clock") == "virtual" for s in meta.get("sessions", []))


def emulator_config(run: Run) -> dict[str, Any] | None:
    """The run config's [sim] table if every device was emulated, else None."""
    return (run.config.get("sim") or None) if all_emulated(run.meta) else None


def _sessions(meta: Mapping[str, Any]) -> list[dict[str, Any]]:
    """Per session: when it started, which devices were emulated and each device as it
    reported itself (its endpoint only, for runs recorded before device identities)."""
    out = []
    for i, s in enumerate(meta.get("sessions", [])):
        devices = s.get("devices") or {name: {"endpoint": endpoint}
                                       for name, endpoint in s.get("endpoints", {}).items()}
        out.append({"session": i, "start_utc": s.get("start_utc"), "emulated": s.get("sim"),
                    "devices": devices})
    return out


def run_record(run: Run) -> dict[str, Any]:
    """The run's record, flat and ordered: run facts (`calibrates`: what a calibration run
    measures, None for a BSDF run; status, reason and gonio.completeness's facts: complete,
    stored_readings, planned_readings), the optics and source, the sample, the environment,
    the provenance, the calibration and the devices per session (None where the run does not
    know a value)."""
    meta = run.meta
    optics = meta.get("optics")
    if optics is None and "optics" in run.config:
        optics = optics_of_config(run.config, "run config").to_json()
    sample = meta.get("sample")
    if sample is None and "sample" in run.plan:
        sample = sample_of_plan(run.plan, "run plan").to_json()
    o = optics or {}
    wavelength = o.get("wavelength_nm", run.config.get("detector", {}).get("wavelength_nm"))
    return {
        "run": run.path.name, "plan": meta.get("plan_name"),
        "calibrates": meta.get("calibrates"),
        "instrument": meta.get("instrument_name"), **completeness_of(run).to_json(),
        "started_utc": meta.get("started_utc"),
        "stopped_utc": meta.get("stopped_utc"), "emulated": meta.get("sim"),
        "seeds": meta.get("seeds", {}),
        "wavelength_nm": wavelength, "bandwidth_nm": o.get("bandwidth_nm"),
        "receiver_solid_angle_sr": o.get("receiver_solid_angle_sr"),
        "receiver_half_angle_deg": o.get("aperture_half_angle_deg"),
        "aperture_diameter_mm": o.get("aperture_diameter_mm"),
        "aperture_distance_mm": o.get("aperture_distance_mm"),
        "beam_diameter_mm": o.get("beam_diameter_mm"),
        "beam_divergence_half_angle_deg": o.get("divergence_deg"),
        "source_polarisation": o.get("source_polarisation"),
        "analyser_polarisation": o.get("analyser_polarisation"),
        "light_source": {key: o.get(key) for key in SOURCE_KEYS},
        "detector": run.config.get("detector", {}).get("device"),
        "detector_spectral_range_nm": o.get("detector_spectral_range_nm"),
        "sample": sample, "environment": _json(run_environment(run)),
        "provenance": _json(provenance_of_config(run.config, "run config")),
        "calibration": meta.get("calibration"),
        "sessions": _sessions(meta),
    }


def run_environment(run: Run) -> Environment | None:
    """The run's environment: its environment sensor's readings summed up, if its config has
    a sensor; else the plan's [environment]; None when neither says."""
    sensor = sensor_of_config(run.config)
    if sensor is not None:
        return environment_of_lines(run.rows(), sensor)
    return environment_of_plan(run.plan, "run plan")


def _json(block: Any) -> dict[str, Any] | None:
    """A block's to_json(), None for a block the run does not have."""
    return None if block is None else block.to_json()


def record_lines(record: Mapping[str, Any]) -> list[str]:
    """`key: value` lines of a record, each value as JSON (one line, parseable back)."""
    return [f"{key}: {json.dumps(value, ensure_ascii=False)}" for key, value in record.items()]
