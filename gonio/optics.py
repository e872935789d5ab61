"""The bench's optics as the experimenter knows them: the instrument config's [optics] table.

The source (what it is, its power), its wavelength and bandwidth, the beam at the sample, the
receiver aperture (so the receiver solid angle), the detector's spectral range and the
polarisation of source and analyser. Reduction, fits, plots and exports read these, never the
emulator's [sim] truth; the record of every run carries them (ASTM E2387, ISO 19986: the data
hold only for this wavelength, geometry and polarisation).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

from gonio.errors import ConfigError
from gonio.fields import Fields, stored_table

#: Polarisation states a source or an analyser may have (or a linear angle in degrees).
POLARISATIONS = ("unpolarised", "s", "p")
#: The keys that describe the source and the detector's range: facts that reduction and fits
#: never read (the BiRD export's, which may take them at export time).
DESCRIPTIVE_KEYS = ("source_name", "source_type", "source_power_mw", "u_source_power_mw",
                    "detector_spectral_range_nm")


@dataclass(frozen=True)
class Optics:
    """[optics]: lengths in mm, angles in degrees (divergence is the half-angle); a polarisation
    is "unpolarised", "s", "p" or a linear polariser's angle in degrees;
    aperture_diameter_tolerance_mm: the aperture diameter's +-tolerance, None when not stated
    (the uncertainty budget then takes a machined part's tolerance class, calibration.type_b);
    the source's name (make and model), type ("HeNe laser", "LED", ...) and power at the
    sample in mW with its standard uncertainty, and the detector's spectral response range
    in nm: "" or None when not stated (the BiRD export needs them)."""

    wavelength_nm: float
    bandwidth_nm: float
    beam_diameter_mm: float
    divergence_deg: float
    aperture_diameter_mm: float
    aperture_distance_mm: float
    source_polarisation: str | float
    analyser_polarisation: str | float
    aperture_diameter_tolerance_mm: float | None = None
    source_name: str = ""
    source_type: str = ""
    source_power_mw: float | None = None
    u_source_power_mw: float | None = None
    detector_spectral_range_nm: tuple[float, float] | None = None

    @property
    def aperture_half_angle_deg(self) -> float:
        """Half-angle the receiver aperture subtends at the sample."""
        return math.degrees(math.atan(0.5 * self.aperture_diameter_mm
                                      / self.aperture_distance_mm))

    @property
    def receiver_solid_angle_sr(self) -> float:
        """Solid angle of the receiver aperture seen from the sample: 2 pi (1 - cos beta)."""
        return 4.0 * math.pi * math.sin(0.5 * math.radians(self.aperture_half_angle_deg)) ** 2

    def to_json(self) -> dict[str, Any]:
        """The table's values plus the derived receiver half-angle and solid angle."""
        return {**asdict(self), "aperture_half_angle_deg": self.aperture_half_angle_deg,
                "receiver_solid_angle_sr": self.receiver_solid_angle_sr}


def _polarisation(f: Fields, key: str) -> str | float:
    value = f._get(key, "unpolarised")
    if isinstance(value, str) and value not in POLARISATIONS:
        raise f.fail(key, f'must be "unpolarised", "s", "p" or a linear polariser\'s angle in '
                     f"degrees; got {value!r}")
    if isinstance(value, str):
        return value
    return f.number(key, low=-180.0, high=180.0)


def parse_descriptive(f: Fields) -> dict[str, Any]:
    """The DESCRIPTIVE_KEYS of an [optics] table, checked: the source's power > 0 with an
    uncertainty only beside it, the detector's range in wavelengths > 0."""
    out = {"source_name": f.string("source_name", ""),
           "source_type": f.string("source_type", ""),
           "source_power_mw": f.number("source_power_mw", None, low=0.0, high=1e9,
                                       low_open=True),
           "u_source_power_mw": f.number("u_source_power_mw", None, low=0.0, high=1e9),
           "detector_spectral_range_nm": f.pair("detector_spectral_range_nm", None)}
    spectral = out["detector_spectral_range_nm"]
    if spectral is not None and spectral[0] <= 0.0:
        raise f.fail("detector_spectral_range_nm", f"must be wavelengths > 0 nm, got "
                     f"[{spectral[0]:g}, {spectral[1]:g}]")
    if out["u_source_power_mw"] is not None and out["source_power_mw"] is None:
        raise f.fail("u_source_power_mw", "needs source_power_mw (the value it is the "
                     "uncertainty of)")
    return out


def parse_optics(f: Fields) -> Optics:
    """Validate an [optics] table (the geometry's and wavelength's keys are required; the
    polarisations, the tolerance, the source's and the detector's range are not)."""
    optics = Optics(
        wavelength_nm=f.number("wavelength_nm", low=200.0, high=20000.0),
        bandwidth_nm=f.number("bandwidth_nm", low=0.0, high=1000.0),
        beam_diameter_mm=f.number("beam_diameter_mm", low=0.0, high=1000.0, low_open=True),
        divergence_deg=f.number("divergence_deg", low=0.0, high=10.0),
        aperture_diameter_mm=f.number("aperture_diameter_mm", low=0.0, high=1000.0,
                                      low_open=True),
        aperture_distance_mm=f.number("aperture_distance_mm", low=0.0, high=10000.0,
                                      low_open=True),
        source_polarisation=_polarisation(f, "source_polarisation"),
        analyser_polarisation=_polarisation(f, "analyser_polarisation"),
        aperture_diameter_tolerance_mm=f.number("aperture_diameter_tolerance_mm", None,
                                                low=0.0, high=100.0),
        **parse_descriptive(f),
    )
    f.done()
    if optics.aperture_diameter_mm >= optics.aperture_distance_mm:
        raise f.fail("aperture_diameter_mm", f"{optics.aperture_diameter_mm:g} mm must be "
                     f"smaller than aperture_distance_mm {optics.aperture_distance_mm:g} mm")
    tolerance = optics.aperture_diameter_tolerance_mm
    if tolerance is not None and tolerance >= optics.aperture_diameter_mm:
        raise f.fail("aperture_diameter_tolerance_mm", f"+-{tolerance:g} mm must be smaller "
                     f"than aperture_diameter_mm {optics.aperture_diameter_mm:g} mm")
    return optics


def optics_of_config(config: dict[str, Any], where: str = "config") -> Optics | None:
    """The [optics] of a stored (raw) instrument config, or None if it has none."""
    return stored_table(config, "optics", where, ConfigError, parse_optics)
