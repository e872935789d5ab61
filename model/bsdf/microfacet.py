"""What rough dielectrics and conductors share: parameters, the normal-sampling schemes and their
densities, masking, input handling and the multiple-scattering switch.

Sampling schemes: 'visible' draws normals from the visible-normal distribution D_wi(m);
'walter' draws D(m) m.z with Walter's widened roughness (1.2 - 0.2 sqrt|cos i|) alpha."""

from __future__ import annotations

import numpy as np

from model.bsdf.constants import WALTER_BASE, WALTER_SLOPE, Sampling, enum_names
from model.bsdf.distributions import WITH_KERNELS, make_distribution
from model.bsdf.masking import check_masking, g2_over_cosines, masking_kind
from model.bsdf.vectors import direction_arrays, directions, dot

SAMPLINGS = enum_names(Sampling)
BACKENDS = ("numba", "numpy")


def walter_widening(cos_i: np.ndarray) -> np.ndarray:
    """Walter's (2007, eq. 47) roughness scale for sampling: 1.2 - 0.2 sqrt|cos i|
    (primitives.walter_scale, vectorised)."""
    return WALTER_BASE - WALTER_SLOPE * np.sqrt(np.abs(cos_i))


class MicrofacetModel:
    """Base of RoughDielectric and RoughConductor: distribution, masking, sampling, MS switch."""

    def __init__(self, distribution, alpha, masking, sampling, multiple_scattering, backend):
        self.distribution = make_distribution(distribution, alpha)
        self.masking = check_masking(masking)
        d = self.distribution
        if sampling is None:
            sampling = d.default_sampling
        if sampling not in SAMPLINGS:
            raise ValueError(f"sampling must be one of {SAMPLINGS}, got {sampling!r}")
        if sampling == "visible" and not d.visible_sampler:
            raise ValueError(f"sampling='visible' is not available for {d.name}; use 'walter'")
        self.sampling = sampling
        self.backend = self._choose_backend(backend)
        self.multiple_scattering = bool(multiple_scattering)
        self._random_walk = None
        if self.multiple_scattering:
            from model.bsdf.multiple_scattering import RandomWalkBSDF

            self._random_walk = RandomWalkBSDF(self)

    # --- public contract -------------------------------------------------------------

    def eval(self, wi, wo, rng: np.random.Generator | None = None) -> np.ndarray:
        """BSDF value f(wi, wo) in 1/sr, no cosine factor; wi, wo (..., 3) broadcast."""
        if self._random_walk is not None:
            return self._random_walk.eval(wi, wo, self._need_rng(rng))
        return self._pairs(wi, wo, want_pdf=False)

    def pdf(self, wi, wo, rng: np.random.Generator | None = None) -> np.ndarray:
        """Density over solid angle of wo of the directions sample() returns (valid ones)."""
        if self._random_walk is not None:
            return self._random_walk.pdf(wi, wo, self._need_rng(rng))
        return self._pairs(wi, wo, want_pdf=True)

    def eval_mueller(self, wi, wo, rng: np.random.Generator | None = None) -> np.ndarray:
        """Mueller BSDF (..., 4, 4) in 1/sr, no cosine, in the Stokes frames of docs/bsdf.md
        (Polarisation): single scattering, M00 = the single-scattering eval. With
        multiple_scattering (rng= needed) the walk's orders >= 2 are added to M00 alone, as
        unpolarised light (an ideal depolariser)."""
        single = self._pairs(wi, wo, want_pdf=False)
        shape = single.shape
        if self.backend == "numba":
            flat = (a.reshape(-1, 3) for a in direction_arrays(wi, wo))
            out = self._mueller_kernel(*flat, single.reshape(-1))
        else:
            wi_u, wo_u = directions(wi, wo)
            with np.errstate(divide="ignore", invalid="ignore"):  # pairs outside lobes masked
                polarised = self._mueller_shape(wi_u.reshape(-1, 3), wo_u.reshape(-1, 3))
            out = single.reshape(-1)[:, None, None] * polarised
        if self._random_walk is not None:
            higher = self._random_walk.eval(wi, wo, self._need_rng(rng), min_order=2)
            out[:, 0, 0] += higher.reshape(-1)
        return out.reshape(shape + (4, 4))

    def sample(self, wi, u, rng: np.random.Generator | None = None):
        """(wo, weight, pdf) from uniforms u (..., 3); weight = f |cos o| / pdf.

        A failed sample (facet turned away, direction on the wrong side of the surface,
        total internal reflection in a transmission-only model) has wo = 0, weight 0, pdf 0.
        """
        if self._random_walk is not None:
            return self._random_walk.sample(wi, u, self._need_rng(rng))
        u = np.asarray(u, dtype=np.float64)
        if u.ndim == 0 or u.shape[-1] != 3:
            raise ValueError(f"u must have shape (..., 3), got {u.shape}")
        (wi,) = direction_arrays(wi)  # normalised by each _sample (the kernels do it inline)
        full = np.broadcast_shapes(wi.shape, u.shape)
        wi, u = np.broadcast_to(wi, full), np.broadcast_to(u, full)
        shape = full[:-1]
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):  # failures masked
            # reshape keeps broadcast (stride-0) views: one wi for many u is not copied
            wo, weight, pdf = self._sample(wi.reshape(-1, 3), u.reshape(-1, 3))
        return wo.reshape(shape + (3,)), weight.reshape(shape), pdf.reshape(shape)

    # --- shared pieces -----------------------------------------------------------------

    def _need_rng(self, rng):
        if not isinstance(rng, np.random.Generator):
            raise ValueError("multiple_scattering=True needs rng= (a numpy.random.Generator)")
        return rng

    def _choose_backend(self, backend):
        """'numba' when its kernel exists, numba imports and alpha is one value (the kernels
        take scalar roughness), else 'numpy' (the reference, which broadcasts alpha arrays)."""
        if backend not in (None, *BACKENDS):
            raise ValueError(f"backend must be one of {BACKENDS} or None, got {backend!r}")
        if backend == "numpy":
            return "numpy"
        from model.bsdf.kernels import AVAILABLE

        d = self.distribution
        scalar_alpha = np.ndim(d.alpha_x) == 0 and np.ndim(d.alpha_y) == 0
        if AVAILABLE and d.kernel is not None and scalar_alpha:
            return "numba"
        if backend == "numba":
            raise ValueError(f"backend='numba' needs numba (pip install 'gonio[fast]'), "
                             f"distribution {' or '.join(WITH_KERNELS)} and one alpha value, got "
                             f"{d.name!r} with alpha shape {np.shape(d.alpha_x)}")
        return "numpy"

    def _pairs(self, wi, wo, want_pdf):
        """eval or pdf over broadcast pairs, by the compiled kernel or the numpy reference."""
        if self.backend == "numba":
            wi, wo = direction_arrays(wi, wo)
            shape = wi.shape[:-1]
            flat = (a.reshape(-1, 3) for a in (wi, wo))  # views, broadcast ones too: no copy
            return self._kernel(*flat, want_pdf).reshape(shape)
        wi, wo = directions(wi, wo)
        shape = wi.shape[:-1]
        fn = self._pdf if want_pdf else self._eval
        with np.errstate(divide="ignore", invalid="ignore"):  # degenerate pairs are masked
            return fn(wi.reshape(-1, 3), wo.reshape(-1, 3)).reshape(shape)

    def _compiled_sampling(self):
        """True when sample() runs in a compiled kernel (Distribution.compiled_samplings)."""
        return (self.backend == "numba"
                and self.sampling in self.distribution.compiled_samplings)

    def _kernel_parameters(self):
        """(ndf, alpha_x, alpha_y, masking, sampling): the parameters every compiled kernel
        takes, as their typed identities and floats."""
        d = self.distribution
        return (d.kernel, float(d.alpha_x), float(d.alpha_y), masking_kind(self.masking),
                Sampling[self.sampling.upper()])

    def __repr__(self) -> str:
        return (f"{type(self).__name__}({self.distribution!r}, {self._material_repr()}, "
                f"masking={self.masking!r}, sampling={self.sampling!r}{self._lobes_repr()})")

    def _lobes_repr(self) -> str:
        return ""

    def _g2_over_cosines(self, wi, wo):
        """G2(wi, wo) / (|cos i| |cos o|), finite at grazing (facet sides checked by callers);
        a pair on opposite sides of the surface is a transmission pair."""
        d = self.distribution
        ci = np.abs(wi[..., 2])
        co = np.abs(wo[..., 2])
        return g2_over_cosines(self.masking, ci, co, d.cos_lambda(wi), d.cos_lambda(wo),
                               wi[..., 2] * wo[..., 2] < 0)

    def _sampling_distribution(self, wi_up):
        return self.distribution.scaled(walter_widening(wi_up[..., 2]))

    def _normal_pdf(self, wi_up, m):
        """Density over solid angle of the normal m drawn for wi_up (wi_up.z >= 0)."""
        if self.sampling == "visible":
            return self.distribution.pdf_visible(wi_up, m)
        return self._sampling_distribution(wi_up).pdf_normal(m)

    def _sample_normal(self, wi_up, u1, u2):
        if self.sampling == "visible":
            return self.distribution.sample_visible(wi_up, u1, u2)
        return self._sampling_distribution(wi_up).sample_normal(u1, u2)

    def _sampling_weight(self, wi_up, wo, m):
        """f |cos o| / pdf without the Fresnel and lobe-choice factors, for normal m.

        visible: G2 / G1(wi); walter: D / D_s * (wi.m) G2 / (|cos i| m.z).
        """
        ci = wi_up[..., 2]
        co = np.abs(wo[..., 2])
        g2oc = self._g2_over_cosines(wi_up, wo)
        if self.sampling == "visible":
            return co * (ci + self.distribution.cos_lambda(wi_up)) * g2oc
        d_s = self._sampling_distribution(wi_up).D(m)
        ok = (d_s > 0) & (m[..., 2] > 0)
        d_s = np.where(ok, d_s, 1.0)
        mz = np.where(ok, m[..., 2], 1.0)
        return np.where(ok, self.distribution.D(m) / d_s * dot(wi_up, m) * co * g2oc / mz, 0.0)


def identity_muellers(n: int) -> np.ndarray:
    """n 4x4 identity matrices, the shape a Mueller matrix takes where the BSDF is 0."""
    return np.tile(np.eye(4), (n, 1, 1))


def reflect(w: np.ndarray, m: np.ndarray) -> np.ndarray:
    """Mirror direction of w about the normal m."""
    return 2.0 * dot(w, m)[..., None] * m - w


def half_vector(wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """Reflection half vector, unit, on the side of wi + wo."""
    h = wi + wo
    return h * (1.0 / np.sqrt(dot(h, h)))[..., None]
