"""Instrument configs (TOML): devices, axes, detector, safety, beam/dark/signature positions,
optics, provenance, [sim].

`load_config(path)` parses and validates a file into an `InstrumentConfig`; every error is a
one-line ConfigError naming the file and the field. The raw (path-resolved) dict is kept for
the run store and for the emulators, which read the [sim] section themselves.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from gonio.device_kinds import KINDS, DeviceConfig
from gonio.device_kinds.kind import AxisConfig
from gonio.device_kinds.line_checks import check_shared_links
from gonio.device_kinds.settings import read_settings
from gonio.errors import ConfigError
from gonio.fields import REQUIRED, Fields, location, read_toml
from gonio.optics import Optics, parse_optics
from gonio.provenance import Provenance, parse_provenance

ROLES = ("sample", "arm", "azimuth", "elevation")

#: The largest axis limit, speed, acceleration and detector range a config may give: far above
#: any bench, and finite, so that no motion time or range arithmetic overflows or vanishes.
MAX_ANGLE_DEG = 1e5
MAX_SPEED_DEG_S = 1e4
MAX_ACCEL_DEG_S2 = 1e6
MAX_RANGE_W = 1e3


@dataclass(frozen=True)
class DetectorConfig:
    """The detector, its correction wavelength, averaging and range policy (None = auto);
    `shot_noise_w`: the shot-noise variance of one sample per watt of signal, W (2 q B / R for
    a photodiode of responsivity R and noise bandwidth B), None when not known;
    `linearity_rel`: the relative 1-sigma non-linearity of a reading and `range_gain_rel` the
    relative 1-sigma gain error of each range (the uncertainty budget's, a datasheet's or a
    test's figures), None when not stated (the detector kind's declared ones then apply)."""

    device: str
    wavelength_nm: float
    averaging: int = 1
    range_w: float | None = None
    shot_noise_w: float | None = None
    linearity_rel: float | None = None
    range_gain_rel: float | None = None


@dataclass(frozen=True)
class Position:
    """A fixed stage position (for beam and dark readings), degrees; a [signature] position
    fixes the sample only (arm_deg None: the arm goes where the sample readings go)."""

    sample_deg: float
    arm_deg: float | None


@dataclass(frozen=True)
class InstrumentConfig:
    """A validated instrument config; `raw` is the TOML dict with paths made absolute."""

    name: str
    path: Path | None
    devices: dict[str, DeviceConfig]
    axes: dict[str, AxisConfig]
    detector: DetectorConfig
    beam_clearance_deg: float
    arm_forbidden_deg: tuple[tuple[float, float], ...]
    beam: Position | None
    dark: Position | None
    raw: dict[str, Any] = field(repr=False)
    optics: Optics | None = None
    signature: Position | None = None  # [signature]: the sample retracted (arm_deg None)
    provenance: Provenance | None = None  # [provenance]: the lab, contact and licence
    environment: str | None = None  # the environment sensor read at every reading, if any

    @property
    def sim(self) -> dict[str, Any]:
        """The [sim] section (empty if none)."""
        return self.raw.get("sim", {})


def load_config(path: str | Path) -> InstrumentConfig:
    """Read and validate an instrument config file."""
    path = Path(path)
    return parse_config(read_toml(path, "instrument config", ConfigError), path)


def parse_config(raw: dict[str, Any], path: str | Path | None = None) -> InstrumentConfig:
    """Validate a config dict; relative register-map paths resolve against `path`'s folder."""
    path = Path(path) if path is not None else None
    where = str(path) if path else "config"
    raw = copy.deepcopy(raw)
    top = Fields(raw, where, ConfigError)
    name = top.string("name", default=path.stem if path else "instrument")
    devices = _devices(top.table_of("devices"), path)
    axes = _axes(top.table_of("axes"), devices)
    optics = parse_optics(top.table_of("optics")) if top.has("optics") else None
    detector = _detector(top.table_of("detector"), devices, optics)
    safety = top.table_of("safety")
    clearance = safety.number("beam_clearance_deg", default=5.0, low=0.0, high=90.0)
    forbidden = _zones(safety)
    safety.done()
    _check_devices(devices, axes, where)
    beam = _position(top, "beam")
    dark = _position(top, "dark")
    signature = _position(top, "signature", arm=False)
    provenance = parse_provenance(top.table_of("provenance")) if top.has("provenance") else None
    if top.has("sim") and not isinstance(raw["sim"], dict):
        raise ConfigError(f"{location(where, 'sim')}: must be a table")
    top.done()
    for dev in devices.values():  # write resolved paths back for the store and emulators
        for setting in dev.kind.settings:
            if setting.type == "file" and setting.key in dev.settings:
                raw["devices"][dev.name][setting.key] = dev.settings[setting.key]
    return InstrumentConfig(name, path, devices, axes, detector, clearance, forbidden,
                            beam, dark, raw, optics, signature, provenance,
                            environment_sensor(devices, where))


def _devices(f: Fields, path: Path | None) -> dict[str, DeviceConfig]:
    """[devices]: each device's protocol names its kind, whose settings it is read by."""
    if not f.table:
        raise ConfigError(f"{f.where}: at least one device is needed")
    base = path.parent if path else Path.cwd()
    out = {}
    for name in f.table:
        d = f.table_of(name)
        kind = KINDS[d.string("protocol", choices=tuple(KINDS))]
        settings = read_settings(d, kind.settings, base)
        d.done()
        out[name] = DeviceConfig(name, kind, settings)
    f.done()
    return out


def _axes(f: Fields, devices: dict[str, DeviceConfig]) -> dict[str, AxisConfig]:
    for role in f.table:
        if role not in ROLES:
            raise ConfigError(f"{f.where}: unknown axis role {role!r} (roles: {', '.join(ROLES)})")
    for role in ("sample", "arm"):
        if role not in f.table:
            raise ConfigError(f"{f.where}: the {role!r} axis is required")
    out, used = {}, {}
    for role in ROLES:
        if role not in f.table:
            continue
        a = f.table_of(role)
        device = a.string("device")
        if device not in devices:
            raise a.fail("device", f"no device {device!r} under [devices]")
        if devices[device].kind.role != "stage":
            raise a.fail("device", f"{device!r} is a {devices[device].protocol}, not a stage")
        axis = a.number("axis", 1, low=1, high=99, integer=True)
        if (device, axis) in used:
            raise a.fail("axis", f"{device} axis {axis} is already the {used[device, axis]!r} axis")
        used[device, axis] = role
        limits = a.pair("limits_deg", low=-MAX_ANGLE_DEG, high=MAX_ANGLE_DEG)
        out[role] = AxisConfig(
            role=role, device=device, axis=axis, limits_deg=limits,
            speed_deg_s=a.number("speed_deg_s", low=0.0, high=MAX_SPEED_DEG_S, low_open=True),
            accel_deg_s2=a.number("accel_deg_s2", low=0.0, high=MAX_ACCEL_DEG_S2,
                                  low_open=True),
            settle_s=a.number("settle_s", 0.0, low=0.0, high=3600.0),
            tolerance_deg=a.number("tolerance_deg", 0.01, low=0.0, high=10.0, low_open=True),
            home=a.boolean("home", False),
            repeatability_deg=a.number("repeatability_deg", 0.0, low=0.0, high=10.0),
        )
        a.string("units", "deg", choices=("deg",))
        a.done()
    return out


def _check_devices(devices: dict[str, DeviceConfig], axes: dict[str, AxisConfig],
                   where: str) -> None:
    """Each kind's own checks of its devices (a Modbus map bounds what a drive accepts, the
    devices of a Zaber chain agree on its line), and no two devices on one device file or
    resource unless they share a bus, before motion."""
    for dev in devices.values():
        if dev.kind.check is not None:
            dev.kind.check(dev, [ax for ax in axes.values() if ax.device == dev.name], where,
                           devices)
    check_shared_links(devices, where)


def environment_sensor(devices: dict[str, DeviceConfig], where: str) -> str | None:
    """The one device of an environment kind (None: none); a ConfigError naming the second."""
    sensors = [name for name, dev in devices.items() if dev.kind.role == "environment"]
    if len(sensors) > 1:
        raise ConfigError(f"{location(where, f'devices.{sensors[1]}')}: a second environment "
                          f"sensor; the config has {sensors[0]!r} already (one is read at every "
                          f"reading)")
    return sensors[0] if sensors else None


def _detector(f: Fields, devices: dict[str, DeviceConfig], optics: Optics | None
              ) -> DetectorConfig:
    """[detector]; its correction wavelength defaults to [optics] wavelength_nm and may not
    differ from it (a meter corrected for another wavelength misreads the source)."""
    device = f.string("device")
    if device not in devices:
        raise f.fail("device", f"no device {device!r} under [devices]")
    if devices[device].kind.role != "detector":
        raise f.fail("device", f"{device!r} is a {devices[device].protocol}, not a detector")
    rng = f._get("range", "auto")
    if rng == "auto":
        range_w = None
    else:
        range_w = f.number("range", low=0.0, high=MAX_RANGE_W, low_open=True)
    wavelength = f.number("wavelength_nm", optics.wavelength_nm if optics else REQUIRED,
                          low=200.0, high=2000.0)
    if optics is not None and abs(wavelength - optics.wavelength_nm) > 1e-6:
        raise f.fail("wavelength_nm", f"{wavelength:g} nm differs from [optics] wavelength_nm "
                     f"{optics.wavelength_nm:g} nm (the meter must be corrected for the "
                     f"source's wavelength)")
    det = DetectorConfig(
        device=device,
        wavelength_nm=wavelength,
        averaging=f.number("averaging", 1, low=1, high=100_000, integer=True),
        range_w=range_w,
        shot_noise_w=f.number("shot_noise_w", None, low=0.0, high=1.0),
        linearity_rel=f.number("linearity_rel", None, low=0.0, high=0.5),
        range_gain_rel=f.number("range_gain_rel", None, low=0.0, high=0.5),
    )
    f.done()
    return det


def _zones(f: Fields) -> tuple[tuple[float, float], ...]:
    zones = f._get("arm_forbidden_deg", [])
    if not isinstance(zones, list):
        raise f.fail("arm_forbidden_deg", "must be a list of [lo, hi] pairs")
    out = []
    for i, zone in enumerate(zones):
        key = f"arm_forbidden_deg[{i}]"
        out.append(Fields({key: zone}, f.source, ConfigError, f.name).pair(key, low=-360.0,
                                                                         high=360.0))
    return tuple(out)


def _position(top: Fields, key: str, arm: bool = True) -> Position | None:
    """[beam], [dark] (sample_deg, arm_deg) or, without `arm`, [signature] (sample_deg)."""
    if not top.has(key):
        return None
    f = top.table_of(key)
    pos = Position(f.number("sample_deg", low=-360.0, high=360.0),
                   f.number("arm_deg", low=-360.0, high=360.0) if arm else None)
    f.done()
    return pos


def angular_distance_deg(arm_deg: Any, elevation_deg: Any = 0.0) -> Any:
    """Angle between the detector direction and the source (+X), degrees (vectorised)."""
    a, e = np.radians(arm_deg), np.radians(elevation_deg)
    return np.degrees(np.arccos(np.clip(np.cos(e) * np.cos(a), -1.0, 1.0)))


def forbidden_reason(cfg: InstrumentConfig, arm_deg: float,
                     elevation_deg: float = 0.0) -> str | None:
    """Why a detector position is forbidden (None if allowed)."""
    dist = float(angular_distance_deg(arm_deg, elevation_deg))
    if dist < cfg.beam_clearance_deg:
        return (f"detector {dist:.3g} deg from the source, inside the beam clearance "
                f"of {cfg.beam_clearance_deg:g} deg")
    for lo, hi in cfg.arm_forbidden_deg:
        if lo <= arm_deg <= hi or lo <= arm_deg - 360 <= hi or lo <= arm_deg + 360 <= hi:
            return f"arm {arm_deg:g} deg inside the forbidden zone [{lo:g}, {hi:g}]"
    return None
