"""Multiple scattering on Smith microsurfaces (Heitz, Hanika, d'Eon, Dachsbacher 2016).

RandomWalkBSDF evaluates, samples and gives the pdf of the full multiple-scattering BSDF of a
rough dielectric, conductor or diffuse microsurface by vectorised random walks; HigherOrderLobe
and higher_orders_at give its orders >= 2 (what single scattering misses) cheaply and
deterministically; energy_loss tells how much energy that is, to decide whether it is needed.
"""

from model.bsdf.multiple_scattering.energy import albedo_estimate, energy_loss
from model.bsdf.multiple_scattering.lobe import HigherOrderLobe, higher_orders_at
from model.bsdf.multiple_scattering.model import Estimate, Microsurface, RandomWalkBSDF

__all__ = ["Estimate", "HigherOrderLobe", "Microsurface", "RandomWalkBSDF", "albedo_estimate",
           "energy_loss", "higher_orders_at"]
