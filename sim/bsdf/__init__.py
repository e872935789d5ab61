"""The microfacet BSDF model: rough dielectric (Walter et al. 2007) and rough conductor."""

from sim.bsdf.conductor import RoughConductor
from sim.bsdf.dielectric import RoughDielectric
from sim.bsdf.distributions import make_distribution
from sim.bsdf.fresnel import fresnel_conductor, fresnel_dielectric

__all__ = [
    "RoughConductor",
    "RoughDielectric",
    "fresnel_conductor",
    "fresnel_dielectric",
    "make_distribution",
]
