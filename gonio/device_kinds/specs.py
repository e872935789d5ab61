"""The type-B specification each device kind declares for the uncertainty budget: a meter's
range-to-range gain accuracy and non-linearity, a stage's bidirectional repeatability, an
environment sensor's temperature and humidity accuracy, each a 1-sigma figure with the
document it comes from (docs/fitting.md, "Uncertainty budget").

A datasheet's uniform +-a becomes a / sqrt(3) (GUM 4.3.7). The Modbus kinds read theirs from
the device's register-map file ([specification]), else take a stated conservative default.
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from drivers.user_file import SETTINGS_FILE_CAP, read_user_text

#: The figures a DeviceSpec holds, each 1-sigma in the unit its name ends with.
FIGURES = ("range_gain_rel", "linearity_rel", "repeatability_deg", "temperature_c",
           "humidity_rel")


@dataclass(frozen=True)
class Figure:
    """One 1-sigma figure and where it comes from (a document and its table, or a config key)."""

    sigma: float
    source: str


def uniform(half_width: float, source: str) -> Figure:
    """The 1-sigma figure of a uniform +-half_width specification, its source saying so."""
    return Figure(half_width / math.sqrt(3.0), f"{source}: +-{half_width:g}, / sqrt(3)")


@dataclass(frozen=True)
class DeviceSpec:
    """A device's declared type-B figures (None: the kind states none)."""

    range_gain_rel: Figure | None = None
    linearity_rel: Figure | None = None
    repeatability_deg: Figure | None = None
    temperature_c: Figure | None = None
    humidity_rel: Figure | None = None


#: A kind's specification of one device, from the device's settings (a register map's file).
SpecOf = Callable[[Mapping[str, Any]], DeviceSpec]


def fixed(spec: DeviceSpec) -> SpecOf:
    """The specification of a kind whose devices all have the same one."""
    return lambda settings: spec


def unverified(source: str, found: str) -> str:
    """A source whose figure has not been checked against the vendor's datasheet, saying what
    the search for it found."""
    return f"{source} (not verified against the datasheet: {found})"


_PM100_SPEC = unverified(
    "Thorlabs PM100USB / PM100D / PM100A operation manuals, technical data, photodiode input "
    "accuracy in % of full scale per current range: its largest figure as every range's own, "
    "independent gain error (a reading and the beam reading it is divided by, on different "
    "ranges, carry both)",
    "the stored copies of the manuals searched give their SCPI chapters, not the table")
_C_SERIES_SPEC = unverified(
    "Thorlabs C-series photodiode sensor heads S120C / S121C specifications, linearity",
    "no Thorlabs sheet reachable; one public third-party uncertainty model of the S121C "
    "states the same +-0.5 %")
PM100 = DeviceSpec(range_gain_rel=uniform(0.005, _PM100_SPEC),
                   linearity_rel=uniform(0.005, _C_SERIES_SPEC))
ESP = DeviceSpec(repeatability_deg=uniform(0.002, unverified(
    "Newport URS75BPP / URS100BPP rotation stages (the ESP301's stepper rotation stages) data "
    "sheet, bidirectional repeatability (guaranteed)",
    "no Newport URS data sheet reachable in the stored sources")))
ZABER = DeviceSpec(repeatability_deg=uniform(0.02, unverified(
    "Zaber X-RSW60A rotary stage (X-series) specifications, repeatability < 0.02 deg",
    "no Zaber X-RSW specification page reachable in the stored sources")))

#: The Modbus kinds' default when the register map states no [specification]: conservative
#: figures for an unnamed drive or amplifier (a 1 % gain-resistor tolerance per range, 1 %
#: non-linearity; a stepper rotation stage's 0.05 deg).
MODBUS_DEFAULT = DeviceSpec(
    range_gain_rel=uniform(0.01, "the Modbus kinds' conservative default (a 1 % gain "
                                 "resistor per range; the register map states none)"),
    linearity_rel=uniform(0.01, "the Modbus kinds' conservative default (the register map "
                                "states none)"),
    repeatability_deg=uniform(0.05, "the Modbus kinds' conservative default (a stepper "
                                    "rotation stage; the register map states none)"))


#: A register map's [specification] key of each figure: the half-width a of a uniform +-a (the
#: 1-sigma figure is a / sqrt(3)), and the largest it may be (a relative one is a fraction,
#: 0.0025 for +-0.25 %; a stage's repeatability in degrees; a sensor's temperature accuracy
#: in deg C, its humidity accuracy as a fraction, 0.03 for +-3 %RH).
MAP_KEYS = {"range_gain_rel": ("range_gain_half_width_rel", 1.0),
            "linearity_rel": ("linearity_half_width_rel", 1.0),
            "repeatability_deg": ("repeatability_half_width_deg", 180.0),
            "temperature_c": ("temperature_half_width_c", 50.0),
            "humidity_rel": ("humidity_half_width_rel", 1.0)}


class UnreadableMap(ValueError):
    """A register map that cannot be read at all (missing, not a regular file, too big)."""


def specification_table(path: Path) -> Mapping[str, Any]:
    """A register-map file's [specification] table ({} without one), checked: `source` a
    string, each figure's key of MAP_KEYS a number in [0, its limit), no other key; a
    ValueError names the file and the key, or why the file cannot be read (a regular file of
    bounded size: drivers.user_file; a TOMLDecodeError: not TOML)."""
    text = read_user_text(path, "register map", SETTINGS_FILE_CAP, UnreadableMap)
    table = tomllib.loads(text).get("specification", {})
    where = f"{path} [specification]"
    if not isinstance(table, Mapping):
        raise ValueError(f"{where}: must be a table")
    limits = dict(MAP_KEYS.values())
    for key, value in table.items():
        if key == "source":
            if not isinstance(value, str):
                raise ValueError(f"{where} source: must be a string, got {value!r}")
        elif key not in limits:
            raise ValueError(f"{where}: unknown key {key!r} (known: source, "
                             f"{', '.join(limits)})")
        elif not (isinstance(value, int | float) and not isinstance(value, bool)
                  and math.isfinite(value) and 0 <= value < limits[key]):
            raise ValueError(f"{where} {key}: must be a number in [0, {limits[key]:g}) (the "
                             f"half-width a of a uniform +-a), got {value!r}")
    return table


def register_map_spec(settings: Mapping[str, Any]) -> DeviceSpec:
    """A Modbus device's figures from its register map's [specification] table (half-widths
    of uniform specifications and their `source`, specification_table), each missing one the
    default's; the default alone when the file cannot be read or its table is not valid
    (its source says so: the config check refuses such a map before a run)."""
    path = Path(str(settings.get("register_map", "")))
    try:
        table = specification_table(path)
    except (UnreadableMap, tomllib.TOMLDecodeError) as exc:
        return _with_note(MODBUS_DEFAULT, f"register map {path} unreadable: {exc}")
    except ValueError as exc:
        return _with_note(MODBUS_DEFAULT, str(exc))
    source = f"{path.name} [specification]: {table.get('source', 'no source named')}"
    return DeviceSpec(**{figure: uniform(float(table[key]), f"{source} ({key})") if key in table
                         else getattr(MODBUS_DEFAULT, figure)
                         for figure, (key, _) in MAP_KEYS.items()})


def _with_note(spec: DeviceSpec, note: str) -> DeviceSpec:
    """`spec` with `note` appended to each figure's source."""
    return DeviceSpec(**{key: Figure(f.sigma, f"{f.source}; {note}")
                         for key in FIGURES if (f := getattr(spec, key)) is not None})
