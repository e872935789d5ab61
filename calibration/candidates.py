"""The model candidates a fit chooses among: every distribution and masking form of model.bsdf's
registries and every model family (the microfacet interface and model.bsdf.families'), by name.
Light to import (no scipy), so that the CLI builds its fit options from it
without loading the fit."""

from model.bsdf.distributions import DISTRIBUTION_NAMES
from model.bsdf.families import FAMILY_NAMES
from model.bsdf.masking import MASKINGS

#: The microfacet interface's family name (RoughDielectric, RoughConductor: calibration.fit.fit).
MICROFACET = "microfacet"
#: Every family a fit can compare: the microfacet interface and the registry's.
FAMILIES = (MICROFACET, *FAMILY_NAMES)

__all__ = ["DISTRIBUTION_NAMES", "FAMILIES", "MASKINGS", "MICROFACET"]
