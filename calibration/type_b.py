"""The type-B figures of a run's uncertainty budget a lab always has: the detector's
non-linearity and range-to-range gain accuracy, each stage's repeatability, the aperture's
dimensional tolerance. Each is the stored config's own figure where it states one, else the
device kind's declared specification (gonio.device_kinds.specs), else (the aperture) a
machined part's tolerance class; each with its source (docs/fitting.md, "Uncertainty budget")."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from gonio.device_kinds import device_spec
from gonio.device_kinds.specs import Figure, uniform
from gonio.optics import Optics

#: ISO 2768-1 table 1 (linear dimensions), tolerance class "f" (fine): (largest nominal size in
#: mm, +- permissible deviation in mm); the class a drawing of a machined aperture calls out when
#: it names no tolerance of its own. The table covers 0.5 mm to 2000 mm (0.5-3 and 3-6 mm both
#: +-0.05; class f has no row above 2000 mm, and sizes below 0.5 mm are to be toleranced on the
#: drawing itself).
ISO_2768_FINE_MM = ((6.0, 0.05), (30.0, 0.1), (120.0, 0.15), (400.0, 0.2), (1000.0, 0.3),
                    (2000.0, 0.5))
ISO_2768_SMALLEST_MM = 0.5


def stated(table: Any, key: str, where: str) -> Figure | None:
    """The config's own 1-sigma figure `key` of a raw table, with its source; None when the
    table does not state it."""
    if isinstance(table, Mapping) and table.get(key) is not None:
        return Figure(float(table[key]), f"the config's {where} {key}")
    return None


def detector_figures(config: Mapping[str, Any]) -> dict[str, Figure]:
    """linearity_rel and range_gain_rel of a stored config's detector: [detector]'s own where
    stated, else its kind's declared ones (left out when neither states one)."""
    detector = config.get("detector", {}) if isinstance(config, Mapping) else {}
    detector = detector if isinstance(detector, Mapping) else {}
    spec = device_spec(config, str(detector.get("device", "")))
    out = {}
    for key in ("linearity_rel", "range_gain_rel"):
        figure = stated(detector, key, "[detector]") or getattr(spec, key)
        if figure is not None:
            out[key] = figure
    return out


def repeatability_figures(config: Mapping[str, Any], roles: tuple[str, ...]
                          ) -> dict[str, Figure]:
    """Each stage role's 1-sigma repeatability, degrees: [axes.ROLE] repeatability_deg where
    stated (0 included), else the kind's declared figure of the device driving it."""
    axes = config.get("axes", {}) if isinstance(config, Mapping) else {}
    out = {}
    for role in roles:
        axis = axes.get(role) if isinstance(axes, Mapping) else None
        if not isinstance(axis, Mapping):
            continue
        figure = (stated(axis, "repeatability_deg", f"[axes.{role}]")
                  or device_spec(config, str(axis.get("device", ""))).repeatability_deg)
        if figure is not None:
            out[role] = figure
    return out


def tolerance_class_mm(diameter_mm: float) -> float:
    """The ISO 2768-f +- deviation of a nominal size (the nearest row outside the table)."""
    return next((dev for top, dev in ISO_2768_FINE_MM if diameter_mm <= top),
                ISO_2768_FINE_MM[-1][1])


def diameter_figure(diameter_mm: float, tolerance_mm: float | None = None) -> Figure:
    """The 1-sigma of an aperture's diameter, mm: a uniform +-t, t the stated tolerance, else
    ISO 2768-f's for the nominal diameter."""
    if tolerance_mm is not None:
        return uniform(tolerance_mm, "the config's [optics] aperture_diameter_tolerance_mm")
    low, high = ISO_2768_SMALLEST_MM, ISO_2768_FINE_MM[-1][0]
    outside = "" if low <= diameter_mm <= high else f" (outside the table's {low:g}-{high:g} " \
                                                    "mm: its nearest row)"
    return uniform(tolerance_class_mm(diameter_mm), f"ISO 2768-1 table 1, class f (fine) "
                   f"tolerance of a machined {diameter_mm:g} mm aperture{outside}")


def _half_angle_per_mm(diameter_mm: float, distance_mm: float) -> tuple[float, float]:
    """(beta, dbeta/dd per mm of diameter), tan beta = d / (2 L)."""
    beta = math.atan(0.5 * diameter_mm / distance_mm)
    return beta, (0.5 / distance_mm) * math.cos(beta) ** 2


def half_angle_sigma_deg(diameter_mm: float, distance_mm: float,
                         tolerance_mm: float | None = None) -> float:
    """The 1-sigma of a nominal aperture's half-angle, degrees, from its diameter's tolerance
    (diameter_figure; the distance taken as exact)."""
    _, dbeta_dd = _half_angle_per_mm(diameter_mm, distance_mm)
    return math.degrees(dbeta_dd * diameter_figure(diameter_mm, tolerance_mm).sigma)


def solid_angle_figure(optics: Optics) -> Figure:
    """The relative 1-sigma of the aperture's solid angle from its diameter's tolerance
    (diameter_figure, [optics] aperture_diameter_tolerance_mm): dOmega/dd = 2 pi sin beta
    dbeta/dd, tan beta = d / (2 L)."""
    sigma_d = diameter_figure(optics.aperture_diameter_mm,
                              optics.aperture_diameter_tolerance_mm)
    beta, dbeta_dd = _half_angle_per_mm(optics.aperture_diameter_mm,
                                        optics.aperture_distance_mm)
    omega = 2.0 * math.pi * (1.0 - math.cos(beta))
    rel = 2.0 * math.pi * math.sin(beta) * dbeta_dd * sigma_d.sigma / omega
    return Figure(rel, f"{sigma_d.source} mm on the diameter")
