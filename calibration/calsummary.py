"""What a calibration file applies to a run, in a few lines: the file, the angle offsets, the
darks and gains per range, the aperture, the reference (`gonio scan --calibration` prints
them)."""

from __future__ import annotations

from calibration.calfile import Calibration
from calibration.values import Measured


def _value(m: Measured, unit: str = "") -> str:
    return f"{m.value:.6g} +- {m.sigma:.2g}{unit}"


def _per_range(values: dict[str, Measured] | None, unit: str = "") -> str:
    if not values:
        return "none"
    return ", ".join(f"{key} W: {_value(m, unit)}"
                     for key, m in sorted(values.items(), key=lambda kv: float(kv[0])))


def applied(cal: Calibration, path: str) -> list[str]:
    """One line each: the file, the angle offsets, the dark offsets, the gains, the aperture,
    the reference; a part the file lacks is said to be none (reduction then does without it)."""
    angles = "none"
    if cal.sample_offset_deg is not None and cal.arm_offset_deg is not None:
        angles = (f"sample {_value(cal.sample_offset_deg, ' deg')}, arm "
                  f"{_value(cal.arm_offset_deg, ' deg')}")
    gains = _per_range(cal.gains)
    if cal.gain_reference is not None:
        gains += f" (relative to {cal.gain_reference} W)"
    aperture = "none"
    if cal.aperture_half_angle_deg is not None and cal.aperture_solid_angle_sr is not None:
        aperture = (f"half-angle {_value(cal.aperture_half_angle_deg, ' deg')}, solid angle "
                    f"{_value(cal.aperture_solid_angle_sr, ' sr')} ({cal.aperture_method})")
    return [f"calibration {path} (created {cal.created_utc}) applies:",
            f"  angle offsets: {angles}",
            f"  dark offsets: {_per_range(cal.dark_offsets_w, ' W')}",
            f"  gains: {gains}",
            f"  aperture: {aperture}",
            f"  reference: {_reference(cal)}"]


def _reference(cal: Calibration) -> str:
    """The reference a calibration normalises to: its certificate and effective solid angle."""
    ref = cal.reference
    if ref is None:
        return "none"
    return (f"{ref.certificate['id']} at {ref.wavelength_nm:g} nm, solid angle "
            f"{_value(ref.solid_angle_sr, ' sr')}, certificate u {ref.certificate_rel:.2%}")
