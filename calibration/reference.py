"""Reference-standard calibration: a run of a certified panel, reduced as any run is, divided by
its certificate gives the bench's effective solid angle (detector signal per beam power, BRDF
and |cos o|), which then replaces the aperture's in every reduction; the certificate's
uncertainty and the reference run's enter each value as shared budget components
(docs/calibration.md, "Reference standards")."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from calibration.certificate import EDGE_TOLERANCE, Certificate
from calibration.reduced import ReducedData
from calibration.values import CalibrationError, Measured

#: The budget's shared components of a reference calibration, and what each is.
COMPONENTS = {"reference_certificate": "the certificate's stated uncertainty",
              "reference_run": "the reference run's noise, beam, dark and range errors"}


@dataclass(frozen=True)
class ReferenceScale:
    """What a reference run determined: `solid_angle_sr`, the effective solid angle (its sigma
    from the reference run), `scale` the reference run's absolute BSDF over the certificate's
    (the nominal solid angle's error and the beam's; 1 on a perfect bench), the relative
    standard uncertainties `certificate_rel` and `run_rel` that every value normalised to it
    shares, and the certificate it came from (id, issuer, date, file, sha256)."""

    certificate: dict[str, Any]
    run: str
    wavelength_nm: float
    solid_angle_sr: Measured
    nominal_solid_angle_sr: float
    scale: Measured
    certificate_rel: float
    run_rel: float
    points: int
    chi2_dof: float

    def to_json(self) -> dict[str, Any]:
        """The calibration file's [reference] section."""
        return {"certificate": self.certificate, "run": self.run,
                "wavelength_nm": self.wavelength_nm,
                "solid_angle_sr": self.solid_angle_sr.to_json(),
                "nominal_solid_angle_sr": self.nominal_solid_angle_sr,
                "scale": self.scale.to_json(), "certificate_rel": self.certificate_rel,
                "run_rel": self.run_rel, "points": self.points, "chi2_dof": self.chi2_dof}

    @classmethod
    def from_json(cls, data: Any, where: str) -> ReferenceScale:
        """Parse the [reference] section; a CalibrationError names the field."""
        if not isinstance(data, dict):
            raise CalibrationError(f"{where}: [reference]: must be a table")

        def number(key: str, low: float = 0.0) -> float:
            try:
                value = float(data[key])
            except (KeyError, TypeError, ValueError):
                raise CalibrationError(f"{where}: [reference] {key}: must be a number") from None
            if not (math.isfinite(value) and value >= low):
                raise CalibrationError(f"{where}: [reference] {key}: must be finite and >= "
                                       f"{low:g}, got {value!r}")
            return value

        certificate = data.get("certificate")
        if not isinstance(certificate, dict) or not {"id", "sha256"} <= set(certificate):
            raise CalibrationError(f"{where}: [reference] certificate: must be a table with "
                                   "the certificate's id and sha256")
        solid = Measured.from_json(data.get("solid_angle_sr"),
                                   f"{where}: [reference] solid_angle_sr")
        if solid.value <= 0:
            raise CalibrationError(f"{where}: [reference] solid_angle_sr: must be > 0")
        return cls(certificate, str(data.get("run", "")), number("wavelength_nm"), solid,
                   number("nominal_solid_angle_sr"),
                   Measured.from_json(data.get("scale"), f"{where}: [reference] scale"),
                   number("certificate_rel"), number("run_rel"), int(number("points")),
                   number("chi2_dof"))

    def check_wavelength(self, wavelength_nm: float) -> None:
        """Refuse a run at another wavelength than the reference's (one CalibrationError)."""
        if not abs(wavelength_nm - self.wavelength_nm) <= EDGE_TOLERANCE["wavelength_nm"]:
            raise CalibrationError(
                f"the calibration's reference run was measured at {self.wavelength_nm:g} nm "
                f"and this run at {wavelength_nm:g} nm: a reference normalises runs at its own "
                "wavelength only (build one from a reference run at this wavelength)")

    def source_of(self, component: str) -> str:
        """What a component (COMPONENTS) comes from: the certificate's id, or the run."""
        return (f"certificate {self.certificate['id']}" if component == "reference_certificate"
                else f"run {self.run}")

    def shared_errors(self, value: np.ndarray) -> dict[str, np.ndarray]:
        """The budget's shared components (COMPONENTS) of values normalised to the reference:
        each one error common to all points, value times its relative uncertainty."""
        value = np.abs(value)
        return {"reference_certificate": value * self.certificate_rel,
                "reference_run": value * self.run_rel}


def relative_azimuth_deg(wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """The azimuth of wo from the plane of incidence, folded into [0, 180] degrees (an isotropic
    panel's BRDF is even in it): 180 on the specular side, 0 back toward the source."""
    phi = np.arctan2(wo[:, 1], wo[:, 0]) - np.arctan2(wi[:, 1], wi[:, 0])
    return np.degrees(np.abs(np.angle(np.exp(1j * phi))))


def scale_from(data: ReducedData, certificate: Certificate, run: str) -> ReferenceScale:
    """The reference calibration from the reference run's absolute reduction `data`: the
    inverse-variance weighted mean c of measured / certified over its valid reflection points
    (own errors only), its chi2/dof (a shape the certificate does not have shows in it; the
    mean's own sigma is scaled by sqrt(chi2/dof) above 1), and the relative errors of c the
    points share (beam, dark, gains), less the solid angle's, which the samples' reductions
    share and which cancels. The effective solid angle is the nominal one times c."""
    use = data.valid & ~data.transmission & (data.bsdf > 0)
    if use.sum() < 2:
        raise CalibrationError(f"{run}: a reference run needs at least two valid reflection "
                               f"points, it has {int(use.sum())}")
    wavelength = float(data.meta.get("wavelength_nm", math.nan))
    if not math.isfinite(wavelength):
        raise CalibrationError(f"{run}: the reference run states no wavelength ([optics] "
                               "wavelength_nm)")
    f_cert, u_cert = certificate.brdf_at(wavelength, data.theta_i_deg[use],
                                         np.abs(data.theta_o_deg[use]),
                                         relative_azimuth_deg(data.wi[use], data.wo[use]))
    own = data.sigma_own[use] / f_cert
    if not np.all(own > 0):
        raise CalibrationError(f"{run}: the reference run's points carry no noise estimate")
    weight = 1.0 / own**2
    weight /= weight.sum()
    ratio = data.bsdf[use] / f_cert
    scale = float(weight @ ratio)
    chi2_dof = float(np.sum((ratio - scale) ** 2 / own**2) / (use.sum() - 1))
    gradient = np.zeros(len(data.bsdf))
    gradient[use] = weight / f_cert
    own_u, shared_u = data.linear_uncertainty(gradient)
    own_u *= math.sqrt(max(chi2_dof, 1.0))
    solid_rel = _median_relative(data, "solid_angle", use)
    run_rel = math.sqrt(own_u**2 + max(shared_u**2 - (scale * solid_rel) ** 2, 0.0)) / scale
    nominal = float(data.meta["aperture_sr"])
    return ReferenceScale(
        certificate=certificate.to_json(), run=run, wavelength_nm=wavelength,
        solid_angle_sr=Measured(nominal * scale, nominal * scale * run_rel),
        nominal_solid_angle_sr=nominal, scale=Measured(scale, scale * run_rel),
        certificate_rel=float(weight @ (u_cert / f_cert)), run_rel=run_rel,
        points=int(use.sum()), chi2_dof=chi2_dof)


def _median_relative(data: ReducedData, name: str, use: np.ndarray) -> float:
    """A component's median u / |f| over the points used (0 if the budget lacks it)."""
    u = data.components.get(name)
    return 0.0 if u is None else float(np.median(u[use] / np.abs(data.bsdf[use])))
