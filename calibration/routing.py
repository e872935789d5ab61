"""Which part of a calibration each run given to `gonio calibrate build` serves: by its plan's
`calibrates` (angles | aperture | detector), a certified panel's run (its [sample] kind
"reference") the reference, else by what its readings hold; a run in a role it cannot serve is
one CalibrationError naming the flag or the run it needs."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from calibration.values import CalibrationError

if TYPE_CHECKING:
    from gonio.store import Run

#: Incidence beyond which the sample is edge-on (retracted): no specular scan there.
RETRACTED_DEG = 89.0
#: The plan that makes an aperture scan.
APERTURE_PLAN = "examples/plans/calib-aperture.toml"
#: The [sample] kind of a certified reference panel, whose run serves the reference.
REFERENCE_KIND = "reference"


def holds_specular_scan(readings: np.ndarray) -> bool:
    """Whether a run's readings scan a specular peak: sample readings on the reflection side
    with the sample in the beam (not edge-on)."""
    return bool(np.any((readings["kind"] == "sample") & (readings["side"] == "reflection")
                       & (np.abs(readings["plan_theta_i_deg"]) < RETRACTED_DEG)))


def role_of(run: Run, readings: np.ndarray) -> str:
    """What a run calibrates: its plan's `calibrates`; a run without it (a plan of one's own)
    serves the reference when its [sample] is a reference panel, the angles when it scans a
    specular peak, else the detector (darks, gains)."""
    stated = run.plan.get("calibrates")
    if stated is not None:
        return str(stated)
    if (run.plan.get("sample") or {}).get("kind") == REFERENCE_KIND:
        return "reference"
    return "angles" if holds_specular_scan(readings) else "detector"


def role_hint(run: Run) -> str:
    """'' for an aperture run or one whose plan states no role; else what to do with it."""
    role = run.plan.get("calibrates")
    if role in (None, "aperture"):
        return ""
    return (f"; the run calibrates the {role} (its plan's calibrates = {role!r}): give it as a "
            f"RUN, and as --aperture-scan a run of {APERTURE_PLAN}")


@dataclass
class Routes:
    """The runs by role: `angles` flags the runs the angle fit takes (one per run given);
    `aperture_scan` is the run to measure the aperture from, `reference` the reference panel's
    run (None: none given)."""

    angles: list[bool]
    aperture_scan: Run | None
    reference: Run | None = None


def route(runs: list[Run], readings: list[np.ndarray], aperture_scan: Run | None,
          geometry_given: bool, certificate_given: bool = False) -> Routes:
    """Route the runs given (with their readings) and the --aperture-scan run (if any): an
    aperture run given as a RUN is the aperture scan; two different aperture scans, or one
    with --aperture-geometry, are refused, and so is an arm scan across the beam whose plan
    does not say so (an aperture scan only by --aperture-scan); a reference panel's run needs
    its certificate (--reference), and the certificate one such run."""
    angles = []
    references = []
    for run, r in zip(runs, readings, strict=True):
        role = role_of(run, r)
        angles.append(role == "angles")
        if role == "reference":
            references.append(run)
            continue
        if role != "aperture":
            if run.plan.get("calibrates") is None and _beam_scan_only(r):
                raise CalibrationError(
                    f"{run.path}: its sample readings all have the sample edge-on, an arm "
                    f"scan across the beam: give it as --aperture-scan {run.path} (or set "
                    f'calibrates = "aperture" in its plan)')
            continue
        if aperture_scan is not None and aperture_scan.path.resolve() != run.path.resolve():
            raise CalibrationError(f"{run.path} and {aperture_scan.path} both scan the aperture "
                                   "(RUN with calibrates = \"aperture\" or --aperture-scan): "
                                   "give one aperture scan")
        if geometry_given:
            raise CalibrationError(f"{run.path} scans the aperture (its plan's calibrates = "
                                   '"aperture") and --aperture-geometry gives it too: drop one')
        aperture_scan = run
    return Routes(angles, aperture_scan, _reference_run(references, certificate_given))


def _reference_run(references: list[Run], certificate_given: bool) -> Run | None:
    """The one reference panel's run when a certificate is given (else none may be)."""
    if not certificate_given:
        if references:
            raise CalibrationError(f"{references[0].path} measures a reference panel (its "
                                   f'[sample] kind = "{REFERENCE_KIND}"): give its certificate '
                                   "with --reference CERT.toml")
        return None
    if len(references) != 1:
        found = ", ".join(str(r.path) for r in references) or "none"
        raise CalibrationError(f"--reference needs exactly one run of the reference panel (a "
                               f'plan whose [sample] kind = "{REFERENCE_KIND}"); found {found}')
    return references[0]


def _beam_scan_only(readings: np.ndarray) -> bool:
    sample = readings[readings["kind"] == "sample"]
    return len(sample) > 0 and bool(np.all(np.abs(sample["plan_theta_i_deg"]) >= RETRACTED_DEG))
