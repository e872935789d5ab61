"""Multiple scattering on Smith microsurfaces (Heitz, Hanika, d'Eon, Dachsbacher 2016).

RandomWalkBSDF evaluates, samples and gives the pdf of the full multiple-scattering BSDF of a
rough dielectric, conductor or diffuse microsurface by vectorised random walks; energy_loss
tells how much energy a single-scattering model misses, to decide whether the walk is needed.
"""

from sim.bsdf.multiple_scattering.energy import albedo_estimate, energy_loss
from sim.bsdf.multiple_scattering.model import Estimate, Microsurface, RandomWalkBSDF

__all__ = ["Estimate", "Microsurface", "RandomWalkBSDF", "albedo_estimate", "energy_loss"]
