"""The model candidates a fit chooses among: every distribution and masking form of model.bsdf's
registries, by name. Light to import (no scipy), so that the CLI builds its fit options from it
without loading the fit."""

from model.bsdf.distributions import DISTRIBUTION_NAMES
from model.bsdf.masking import MASKINGS

__all__ = ["DISTRIBUTION_NAMES", "MASKINGS"]
