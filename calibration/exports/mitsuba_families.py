"""Mitsuba 3 materials of the model families (calibration.exports.family_fit): a `lambert` fit
as Mitsuba's own `diffuse`, whose value it is; a `lambert+microfacet` fit as gonio's
`gonio_coated` plugin (calibration.exports.mitsuba_plugin) around Mitsuba's `roughplastic` with
a black base, whose value is gonio's coat lobe.

Mitsuba's `roughplastic` with the fitted base is not gonio's CoatedDiffuse: its base term is
rho/pi T(i) T(o) / (eta^2 (1 - F_int)), with the coat's transmittance T and its mean internal
reflectance F_int, where gonio's is rho/pi (1 - a(i)) (1 - a(o)) / (1 - a_mean). Measured
against Mitsuba itself, they differ by 2.6 % (rms over a grid of pairs) for a near-smooth coat
to 50 % for alpha 0.5 (docs/fitting.md, tests/fitting/test_exports_families.py), so the export
writes the plugin, which equals gonio's model to float32 rounding (GGX)."""

from __future__ import annotations

from typing import Any

from calibration.exports.family_fit import FamilyFit, check_family
from calibration.exports.mitsuba import PLUGIN_USE, listed

COATED_TYPE = "gonio_coated"
#: The measured mismatch of Mitsuba's roughplastic (one line for the export's notes).
ROUGHPLASTIC_NOTE = ("Mitsuba's own roughplastic with this base is darker than the model (by 2.6 "
                     "% rms for a coat of alpha 0.02 to 50 % for 0.5: its base term carries "
                     "1/eta^2 and the coat's internal reflectance; docs/fitting.md), so the "
                     "material is gonio's gonio_coated plugin around a roughplastic with a "
                     "black base (the coat lobe alone, which is gonio's)")


def family_material(family: FamilyFit) -> tuple[dict[str, Any], list[str]]:
    """(the Mitsuba material of the family fit, the notes that say what it is); a
    CalibrationError for a family Mitsuba cannot hold (family_fit.check_family)."""
    check_family("mitsuba", family.family)
    rho = family.scale * family.values["rho"]
    if family.family == "lambert":
        return ({"type": "diffuse", "params": {"reflectance": rho}},
                ["Lambert: Mitsuba's diffuse of the fitted albedo (the same BRDF, rho / pi)"])
    model = family.model()
    coat: dict[str, Any] = {"distribution": model.distribution.name,
                            "alpha": family.values["alpha"], "int_ior": family.values["eta"],
                            "ext_ior": 1.0, "diffuse_reflectance": 0.0}
    if family.scale != 1.0:
        coat["specular_reflectance"] = family.scale
    table = model.table
    params = {"rho": rho, "albedo_mu": listed(table.mu, 9), "albedo": listed(table.albedo, 9),
              "albedo_mean": table.mean}
    notes = [ROUGHPLASTIC_NOTE, PLUGIN_USE]
    if model.masking != "separable":
        notes.append(f"the fit's coat used {model.masking} masking; Mitsuba's roughplastic "
                     "uses separable Smith")
    return ({"type": COATED_TYPE, "params": params,
             "nested": {"coat": {"type": "roughplastic", "params": coat}}}, notes)
