"""The BSDF models: rough dielectric (Walter et al. 2007) and rough conductor, and the families
beside them (families/: Lambert, Oren-Nayar, a coated diffuse surface, ABg, Rayleigh-Rice).

The models are imported on first use (PEP 562), so that the registries of distributions and
maskings (model.bsdf.distributions, model.bsdf.masking) import without scipy: the CLI builds its
options from them at start-up."""

from __future__ import annotations

import importlib

_HOMES = {
    "ABg": "model.bsdf.families.abg",
    "CoatedDiffuse": "model.bsdf.families.coated",
    "Lambert": "model.bsdf.families.lambert",
    "OrenNayar": "model.bsdf.families.oren_nayar",
    "RayleighRice": "model.bsdf.families.rayleigh_rice",
    "RoughConductor": "model.bsdf.conductor",
    "RoughDielectric": "model.bsdf.dielectric",
    "fresnel_conductor": "model.bsdf.fresnel",
    "fresnel_dielectric": "model.bsdf.fresnel",
    "make_distribution": "model.bsdf.distributions",
    "make_family": "model.bsdf.families",
}

__all__ = sorted(_HOMES)


def __getattr__(name: str):
    """The public name `name`, imported from its module on first use."""
    if name not in _HOMES:
        raise AttributeError(f"module 'model.bsdf' has no attribute {name!r}")
    return getattr(importlib.import_module(_HOMES[name]), name)
