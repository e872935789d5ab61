"""A coated or painted surface: a Fresnel-weighted rough dielectric interface (the microfacet
reflection lobe of RoughDielectric) over a Lambertian base, coupled as Kelemen and
Szirmay-Kalos couple their matte term to the specular one (Eurographics 2001 short paper, "A
microfacet based coupled specular-matte BRDF model with importance sampling"):

    f = f_layer(i, o) + rho / pi * (1 - a(i)) (1 - a(o)) / (1 - a_mean),

a(w) the layer's directional albedo, a_mean = 2 int a(mu) mu dmu its cosine-weighted mean. The
base sees what the layer does not reflect, on the way in and on the way out, so f is reciprocal
and the total albedo is a(i) + rho (1 - a(i)): at most 1, and 1 for a white base (rho = 1),
whatever the layer loses to masking. a(mu) is tabulated once per coat (albedo_table); the
white-furnace error is the table's: at most 3e-4 at 128^2 strata, built in 60-90 ms for a GGX coat
(bench/bsdf_families.py, docs/bsdf-families.md)."""

from __future__ import annotations

import functools
import math

import numpy as np

from model.bsdf.distributions import WITH_KERNELS
from model.bsdf.families.base import Parameter, ReflectionFamily, cosine_hemisphere
from model.bsdf.families.lambert import RHO

ALPHA = Parameter("alpha", 1e-4, 4.0, True, "roughness of the coat's microfacet interface")
ETA = Parameter("eta", 1.0001, 4.0, False, "refractive index of the coat over the exterior")
#: Cosines of incidence at which a(mu) is tabulated: denser toward grazing, where it bends.
TABLE_MU = np.linspace(0.0, 1.0, 49)[1:] ** 2
#: Stratified uniforms per side (TABLE_STRATA^2 per cosine) of the table's sample() sums:
#: the sum errs like 1 / TABLE_STRATA where the lobe meets the horizon (bench/bsdf_families.py).
TABLE_STRATA = 128


class AlbedoTable:
    """The directional albedo a(mu) of a reflection-only microfacet layer, by stratified sums
    of its sample() weights at TABLE_MU, interpolated linearly in mu (held at TABLE_MU[0]
    below it); `mean` is 2 int a(mu) mu dmu of that same interpolant, exactly (two-point
    Gauss-Legendre per piece), so the coupled model's white furnace errs by the interpolant's
    error at the incidence alone."""

    def __init__(self, layer, mu: np.ndarray = TABLE_MU, strata: int = TABLE_STRATA):
        edges = (np.arange(strata) + 0.5) / strata
        u1, u2 = np.meshgrid(edges, edges, indexing="ij")
        u = np.stack([u1.ravel(), u2.ravel(), np.full(u1.size, 0.5)], axis=-1)
        wi = np.stack([np.sqrt(1.0 - mu * mu), np.zeros_like(mu), mu], axis=-1)
        weight = layer.sample(wi[:, None, :], u[None, :, :])[1]
        self.mu, self.albedo = mu, weight.mean(axis=1)
        knots = np.concatenate([[0.0], mu])
        values = np.concatenate([[self.albedo[0]], self.albedo])
        nodes = 0.5 + np.array([-0.5, 0.5]) / math.sqrt(3.0)  # two-point Gauss on [0, 1]
        x = knots[:-1, None] + np.diff(knots)[:, None] * nodes
        y = values[:-1, None] + np.diff(values)[:, None] * nodes
        self.mean = float(2.0 * np.sum(0.5 * np.diff(knots)[:, None] * x * y))

    def __call__(self, mu: np.ndarray) -> np.ndarray:
        """a(mu) at cosines mu in [0, 1]."""
        return np.interp(mu, self.mu, self.albedo)


def coat_layer(distribution: str, alpha: float, eta: float, masking: str):
    """The coat: RoughDielectric's reflection lobe, sampled by the first compiled normal
    sampler of its distribution (visible normals for GGX, Walter's for Beckmann), so that
    sample() and the albedo table run compiled."""
    from model.bsdf.dielectric import RoughDielectric
    from model.bsdf.distributions import DISTRIBUTIONS

    return RoughDielectric(distribution, alpha, eta, masking, lobes=("reflection",),
                           sampling=DISTRIBUTIONS[distribution].compiled_samplings[0])


@functools.lru_cache(maxsize=64)
def albedo_table(distribution: str, alpha: float, eta: float, masking: str) -> AlbedoTable:
    """The coat's AlbedoTable, kept for the last coats built (a fit that moves only rho, or
    returns to a coat, builds it once)."""
    return AlbedoTable(coat_layer(distribution, alpha, eta, masking))


class CoatedDiffuse(ReflectionFamily):
    """Lambert base of albedo rho under a rough dielectric coat (alpha, eta; distribution and
    masking as RoughDielectric takes them), the `lambert+microfacet` family.

    sample() picks the layer's lobe with probability a(i) / (a(i) + rho (1 - a(i))) (its share
    of the reflected energy) and the cosine-weighted base otherwise; pdf() is that mixture."""

    family = "lambert+microfacet"
    PARAMETERS = (RHO, ALPHA, ETA)
    SETTINGS = ("distribution", "masking")

    def __init__(self, rho: float = 0.8, alpha: float = 0.1, eta: float = 1.5,
                 distribution: str = "ggx", masking: str = "separable"):
        if distribution not in WITH_KERNELS:
            raise ValueError(f"distribution must be one of {WITH_KERNELS}, got {distribution!r}")
        super().__init__(rho=rho, alpha=alpha, eta=eta)
        self.layer = coat_layer(distribution, self.alpha, self.eta, masking)
        # the coat's Distribution and masking under the microfacet models' attribute names, so
        # code that sizes its quadrature by model.distribution's alpha sees the coat's lobe
        self.distribution, self.masking = self.layer.distribution, masking
        self.table = albedo_table(distribution, self.alpha, self.eta, masking)

    def settings(self) -> dict:
        """The fixed settings by name: the coat's distribution name and masking form."""
        return {"distribution": self.distribution.name, "masking": self.masking}

    def _base(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        """The base's share rho / pi (1 - a(i)) (1 - a(o)) / (1 - a_mean)."""
        t = self.table
        return (self.rho / math.pi * (1.0 - t(wi[:, 2])) * (1.0 - t(wo[:, 2]))
                / (1.0 - t.mean))

    def _eval(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        return self.layer.eval(wi, wo) + self._base(wi, wo)

    def layer_probability(self, cos_i: np.ndarray) -> np.ndarray:
        """Probability that sample() draws from the layer's lobe at incidence cosine cos_i."""
        a = self.table(cos_i)
        total = a + self.rho * (1.0 - a)
        return np.where(total > 0, a / np.where(total > 0, total, 1.0), 1.0)

    def _pdf(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        p = self.layer_probability(wi[:, 2])
        return p * self.layer.pdf(wi, wo) + (1.0 - p) * wo[:, 2] / math.pi

    def _sample_directions(self, wi: np.ndarray, u: np.ndarray) -> np.ndarray:
        on_layer = u[:, 2] < self.layer_probability(wi[:, 2])
        wo = cosine_hemisphere(u[:, 0], u[:, 1])
        if on_layer.any():  # the coat has one lobe: its sample() leaves u3 unused
            wo[on_layer] = self.layer.sample(wi[on_layer], u[on_layer])[0]
        return wo
