"""RandomWalkBSDF: the multiple-scattering BSDF of a rough conductor, dielectric or diffuse surface.

Built from a single-scattering model (RoughDielectric / RoughConductor build it themselves when
constructed with multiple_scattering=True) or from a Microsurface description. Values follow
docs/architecture.md: 1/sr, no cosine, Walter's eq. 21 for transmission; they are unbiased Monte
Carlo estimates, each the mean of `walks` independent random walks per direction pair.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from model.bsdf.distributions import Distribution, make_distribution
from model.bsdf.multiple_scattering import sample_kernel
from model.bsdf.multiple_scattering.energy import energy_loss
from model.bsdf.multiple_scattering.heights import make_heights
from model.bsdf.multiple_scattering.micro import MicroConductor, MicroDielectric, MicroDiffuse
from model.bsdf.multiple_scattering.walk import Walker, walkable
from model.bsdf.vectors import direction_arrays, directions

KINDS = ("dielectric", "conductor", "diffuse")
#: Guided direction sampling is on by default below this alpha (measured: ~5x less variance
#: per second at alpha 0.3, ~1.4x more at alpha 1.0 for GGX glass).
GUIDE_BELOW_ALPHA = 0.7
#: Walks advanced together in one vectorised batch (bounded so the arrays stay in cache).
BATCH = 1 << 15
#: Incidence angles (deg from the side's normal) of the table of orders >= 2's share behind
#: approximate_pdf (interpolated linearly between them).
MASS_NODES_DEG = (0.0, 15.0, 30.0, 45.0, 60.0, 70.0, 80.0, 85.0, 89.0)


@dataclass(frozen=True)
class Microsurface:
    """A microsurface by parameters, for kinds that have no single-scattering class (diffuse).

    Carries the attributes RandomWalkBSDF reads from a parent model: distribution, eta,
    eta_complex (conductor; None means F = 1), albedo (diffuse facets) and kind.
    """

    distribution: str | Distribution
    alpha: float | tuple[float, float] = 0.5
    kind: str = "dielectric"
    eta: float = 1.5
    eta_complex: complex | None = None
    albedo: float = 1.0


@dataclass
class Estimate:
    """A Monte Carlo estimate per direction pair: value, its standard error, and the energy the
    order cap left inside the surface (0 without a cap; an upper bound of the cap's bias
    integrated over all outgoing directions with the cosine)."""

    value: np.ndarray
    stderr: np.ndarray
    truncated_energy: np.ndarray


def _distribution(parent) -> Distribution:
    dist = parent.distribution
    if isinstance(dist, str):
        return make_distribution(dist, parent.alpha)
    return dist


def _micro(parent):
    kind = getattr(parent, "kind", None)
    if kind is None:
        kind = "conductor" if hasattr(parent, "eta_complex") else "dielectric"
    if kind not in KINDS:
        raise ValueError(f"micro-BSDF kind must be one of {KINDS}, got {kind!r}")
    if kind == "conductor":
        return MicroConductor(parent.eta_complex)
    if kind == "diffuse":
        return MicroDiffuse(parent.albedo)
    eta = float(parent.eta)
    if not (np.isfinite(eta) and eta > 0.0):
        raise ValueError(f"eta must be positive and finite, got {parent.eta!r}")
    return MicroDielectric(eta)


class RandomWalkBSDF:
    """Stochastic multiple-scattering BSDF: eval, pdf and sample by random walks (Heitz 2016).

    walks: walks per direction pair in eval/pdf; max_order: optional cap on scattering orders
    (biased; the bias bound is reported by `estimate`); height: "uniform" or "gaussian" height
    distribution, which changes the recorded heights and nothing else (Smith microsurface);
    guided: draw some next directions backwards from wo when evaluating (see guiding.py);
    None means on below alpha GUIDE_BELOW_ALPHA, where it pays for its cost.
    slopes is its distribution, walker the Walker that runs its batches of walks.
    sample() follows one walk and reports approximate_pdf (not the walk's exact density, which
    only pdf() estimates, by walks): see docs/architecture.md on stochastic models.
    """

    def __init__(self, parent, *, walks: int = 256, max_order: int | None = None,
                 height: str = "uniform", guided: bool | None = None):
        if int(walks) != walks or walks < 1:
            raise ValueError(f"walks must be a positive integer, got {walks!r}")
        if max_order is not None and (int(max_order) != max_order or max_order < 1):
            raise ValueError(f"max_order must be None or a positive integer, got {max_order!r}")
        self.parent = parent
        self.slopes = walkable(_distribution(parent))
        self.micro = _micro(parent)
        self.heights = make_heights(height)
        self.walks = int(walks)
        self.max_order = None if max_order is None else int(max_order)
        if guided is None:
            guided = max(self.slopes.alpha_x, self.slopes.alpha_y) < GUIDE_BELOW_ALPHA
        self.guided = bool(guided)
        self.walker = Walker(self.slopes, self.micro, self.guided)
        self._single = None  # the order-1 model behind approximate_pdf, built on first use
        self._shares: dict[bool, np.ndarray] = {}
        self.share_nodes = np.array(MASS_NODES_DEG, dtype=np.float64)

    def _pairs(self, wi, wo, order, unit, rng, walks, min_order=1) -> tuple[np.ndarray, ...]:
        """Mean, standard error and truncated energy per pair, walking in batches of BATCH;
        orders below min_order are not counted."""
        wi, wo = directions(wi, wo)
        if order is not None and (int(order) != order or order < 1):
            raise ValueError(f"order must be None or a positive integer, got {order!r}")
        shape = wi.shape[:-1]
        wi, wo = wi.reshape(-1, 3), wo.reshape(-1, 3)
        cap = self.max_order if order is None else None
        total = np.zeros((3, wi.shape[0]))  # sum, sum of squares, truncated energy
        per_round = max(1, BATCH // max(1, wi.shape[0]))
        done = 0
        while done < walks:
            k = min(per_round, walks - done)
            res = self.walker.run(np.repeat(wi, k, axis=0), rng, np.repeat(wo, k, axis=0),
                                   order=order, max_order=cap, unit=unit, min_order=min_order)
            v = res.value.reshape(-1, k)
            total += [v.sum(axis=1), (v * v).sum(axis=1), res.truncated.reshape(-1, k).sum(axis=1)]
            done += k
        keep = self._lobe_mask(wi, wo)
        total *= keep
        mean = total[0] / walks
        var = np.maximum(total[1] / walks - mean * mean, 0.0) * walks / max(walks - 1, 1)
        cos_o = np.abs(wo[:, 2])
        scale = np.where(cos_o > 0.0, 1.0 / np.where(cos_o > 0.0, cos_o, 1.0), 0.0)
        err = np.sqrt(var / walks) * scale if walks > 1 else np.full(mean.shape, np.inf)
        return ((mean * scale).reshape(shape), err.reshape(shape),
                (total[2] / walks).reshape(shape))

    def _lobe_mask(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        """1 where the parent's `lobes` (reflection / transmission) include the pair, else 0."""
        same = (wi[..., 2] > 0.0) == (wo[..., 2] > 0.0)
        return np.where(same, "reflection" in self.lobes, "transmission" in self.lobes
                        ).astype(float)

    @property
    def lobes(self) -> tuple[str, ...]:
        """The parent's lobes ("reflection", "transmission"), both if it does not say."""
        return tuple(getattr(self.parent, "lobes", ("reflection", "transmission")))

    def estimate(self, wi, wo, rng: np.random.Generator, *, order: int | None = None,
                 walks: int | None = None, min_order: int = 1) -> Estimate:
        """BSDF estimate with its standard error and the order cap's leftover energy;
        order=k counts the k-th scattering order only, min_order=k the orders from k on."""
        if int(min_order) != min_order or min_order < 1:
            raise ValueError(f"min_order must be a positive integer, got {min_order!r}")
        value, err, trunc = self._pairs(wi, wo, order, False, rng, walks or self.walks,
                                        int(min_order))
        return Estimate(value, err, trunc)

    def eval(self, wi, wo, rng: np.random.Generator, *, order: int | None = None,
             min_order: int = 1) -> np.ndarray:
        """BSDF value f(wi, wo) in 1/sr, no cosine; order and min_order as for estimate."""
        return self.estimate(wi, wo, rng, order=order, min_order=min_order).value

    def pdf(self, wi, wo, rng: np.random.Generator) -> np.ndarray:
        """Density over solid angle of sample()'s wo: the walk's direction density, estimated
        by `walks` walks per pair (unbiased, noisy; approximate_pdf is the deterministic one)."""
        wi_, wo_ = directions(wi, wo)
        f_unit = self._pairs(wi_, wo_, None, True, rng, self.walks)[0]
        return f_unit * np.abs(wo_[..., 2])

    def approximate_pdf(self, wi, wo) -> np.ndarray:
        """The density sample() reports: order 1 of the walk exactly (the height-correlated
        single-scattering model, F = 1 for a conductor) plus orders >= 2 as a cosine lobe
        carrying their share of the walks (energy_loss at wi's incidence, in the x-z plane for
        an anisotropic surface): M |cos o| / pi above a conductor, M |cos o| / (2 pi) on either
        side of a dielectric; diffuse facets: |cos o| / pi. Deterministic and cheap, positive
        wherever the walk reaches, for multiple importance sampling; not the exact density.
        Compiled (sample_kernel) where the walk is."""
        if self.walker.compiled:
            wi_b, wo_b = direction_arrays(wi, wo)
            shape = wo_b.shape[:-1]
            wo_rows = np.ascontiguousarray(wo_b).reshape(-1, 3)
            return sample_kernel.approximate_pdf(self, _rows(wi, wi_b), wo_rows).reshape(shape)
        wi, wo = directions(wi, wo)
        same = (wi[..., 2] > 0.0) == (wo[..., 2] > 0.0)
        cos_o = np.abs(wo[..., 2])
        if isinstance(self.micro, MicroDiffuse):
            return np.where(same, cos_o / np.pi, 0.0)
        first = self._order_one().eval(wi, wo) * cos_o
        mass = self._higher_order_share(wi)
        if isinstance(self.micro, MicroConductor):
            return first + np.where(same & (wi[..., 2] > 0.0), mass * cos_o / np.pi, 0.0)
        return first + mass * cos_o / (2.0 * np.pi)

    def _order_one(self):
        """The single-scattering model equal to the walk's order 1 in unit mode."""
        if self._single is None:
            from model.bsdf import RoughConductor, RoughDielectric

            alpha = (float(self.slopes.alpha_x), float(self.slopes.alpha_y))
            if isinstance(self.micro, MicroConductor):
                self._single = RoughConductor(self.slopes.name, alpha, None,
                                              masking="correlated")
            else:
                self._single = RoughDielectric(self.slopes.name, alpha, self.micro.eta,
                                               masking="correlated")
        return self._single

    def _higher_order_share(self, wi: np.ndarray) -> np.ndarray:
        """Share of the walks from wi that scatter more than once (tabulated energy_loss)."""
        above = wi[..., 2] > 0.0
        theta = np.degrees(np.arccos(np.clip(np.abs(wi[..., 2]), 0.0, 1.0)))
        share = np.zeros(theta.shape)
        for side in (True, False):
            pick = above == side
            if pick.any():
                share[pick] = np.interp(theta[pick], MASS_NODES_DEG, self._share_table(side))
        return share

    def share_tables(self) -> np.ndarray:
        """(2, len(MASS_NODES_DEG)): _share_table from outside, then from inside."""
        return np.array([self._share_table(True), self._share_table(False)])

    def _share_table(self, outside: bool) -> np.ndarray:
        """energy_loss at MASS_NODES_DEG from outside or (a dielectric) from inside."""
        if outside not in self._shares:
            conductor = isinstance(self.micro, MicroConductor)
            if conductor and not outside:
                table = np.zeros(len(MASS_NODES_DEG))
            else:
                eta = None if conductor else (self.micro.eta if outside else 1.0 / self.micro.eta)
                alpha = (float(self.slopes.alpha_x), float(self.slopes.alpha_y))
                table = np.array([energy_loss(self.slopes.name, alpha, eta, np.radians(t))
                                  for t in MASS_NODES_DEG])
            self._shares[outside] = table
        return self._shares[outside]

    def walk_once(self, wi, u, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """One walk from each wi: (wo, weight = the walk's throughput, 0 outside the parent's
        lobes or when the walk does not leave). u (..., 3) drives the first scattering event
        (height, visible normal); later events use rng."""
        (wi,) = directions(wi)
        u = np.asarray(u, dtype=np.float64)
        shape = wi.shape[:-1]
        u = np.broadcast_to(u, shape + (3,)).reshape(-1, 3)
        res = self.walker.run(wi.reshape(-1, 3), rng, u_first=u, max_order=self.max_order)
        ok = np.isfinite(res.exit_direction[:, 0])
        wo = np.where(ok[:, None], res.exit_direction, np.array([0.0, 0.0, 1.0]))
        ok &= self._lobe_mask(wi.reshape(-1, 3), wo) > 0.0
        return wo.reshape(shape + (3,)), np.where(ok, res.weight, 0.0).reshape(shape)

    def sample(self, wi, u, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """walk_once, and approximate_pdf at wo: (wo, weight = f |cos o| / p(wo), pdf).

        One walk per sample: the weight is exact for the walk's own density p; the pdf returned
        is approximate_pdf, not p (p is known only by further walks: pdf()), so use it for MIS
        weights, not to divide by. Compiled (sample_kernel) where the walk is: the walk and
        the pdf in one pass.
        """
        if self.walker.compiled:
            (wi_b,) = direction_arrays(wi)
            shape = wi_b.shape[:-1]
            wi_rows = _rows(wi, wi_b)
            u = np.asarray(u, dtype=np.float64)
            u = np.ascontiguousarray(np.broadcast_to(u, shape + (3,))).reshape(-1, 3)
            wo, weight, pdf = sample_kernel.sample(self, wi_rows, u, rng)
            return wo.reshape(shape + (3,)), weight.reshape(shape), pdf.reshape(shape)
        wo, weight = self.walk_once(wi, u, rng)
        (wi,) = directions(wi)
        pdf = np.where(weight > 0.0, self.approximate_pdf(np.broadcast_to(wi, wo.shape), wo), 0.0)
        return wo, weight, pdf

    def first_heights(self, wi, rng: np.random.Generator, walks: int) -> np.ndarray:
        """Heights of the first scattering event of `walks` walks from wi (nan: none)."""
        (wi,) = directions(wi)
        res = self.walker.run(np.repeat(wi.reshape(1, 3), walks, axis=0), rng, max_order=1)
        return self.heights.inv_log_cdf(res.first_log_cdf)


def _rows(wi, broadcast: np.ndarray) -> np.ndarray:
    """wi as contiguous rows (m, 3), not normalised: one row when wi is one direction, else its
    broadcast view's rows."""
    rows = np.asarray(wi, dtype=np.float64) if np.ndim(wi) == 1 else broadcast
    return np.ascontiguousarray(rows).reshape(-1, 3)
