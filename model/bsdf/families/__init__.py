"""The model families beside the microfacet models, registered once by the name fit results
report (`family`): each a reflection-only model with eval/pdf/sample as RoughDielectric has
them and parameters by name (base.Parameter), so a fit builds any of them from names and values.

The registry names where each family lives; a family's module is imported on first use."""

from __future__ import annotations

import importlib
from collections.abc import Mapping

#: Family name -> (module, class): the one list of the families.
FAMILIES = {
    "lambert": ("model.bsdf.families.lambert", "Lambert"),
    "oren-nayar": ("model.bsdf.families.oren_nayar", "OrenNayar"),
    "lambert+microfacet": ("model.bsdf.families.coated", "CoatedDiffuse"),
    "abg": ("model.bsdf.families.abg", "ABg"),
    "rayleigh-rice": ("model.bsdf.families.rayleigh_rice", "RayleighRice"),
}
FAMILY_NAMES = tuple(FAMILIES)


def family_class(name: str) -> type:
    """The class of the family `name`; a ValueError listing the families for another name."""
    if name not in FAMILIES:
        raise ValueError(f"family must be one of {FAMILY_NAMES}, got {name!r}")
    module, cls = FAMILIES[name]
    return getattr(importlib.import_module(module), cls)


def make_family(name: str, values: Mapping[str, float], **settings):
    """The model of family `name` for parameter values by name (and its fixed settings)."""
    return family_class(name).from_parameters(values, **settings)
