"""What the reflection-only model families share: parameters by name with their bounds (so a fit
can build a family from the names it reports), and eval/pdf/sample over broadcast direction
arrays with the conventions of the microfacet models (1/sr, no cosine factor, +z the normal)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from model.bsdf.constants import COS_HORIZON
from model.bsdf.vectors import direction_arrays, directions, unit


@dataclass(frozen=True)
class Parameter:
    """One named parameter of a family: its admissible range and whether a fit should move it
    in log space (a positive scale), with a one-line meaning for help texts and reports."""

    name: str
    lower: float
    upper: float
    log: bool
    meaning: str

    def check(self, value) -> float:
        """value as a float if it is finite and within [lower, upper]; else a ValueError naming
        the parameter."""
        try:
            x = float(value)
        except (TypeError, ValueError):
            raise ValueError(f"{self.name} must be a number, got {value!r}") from None
        if not (math.isfinite(x) and self.lower <= x <= self.upper):
            raise ValueError(f"{self.name} must be finite and in [{self.lower}, {self.upper}], "
                             f"got {value!r}")
        return x


def cosine_hemisphere(u1: np.ndarray, u2: np.ndarray) -> np.ndarray:
    """Directions above the surface with density cos(theta) / pi over solid angle (Malley's
    method: a uniform point of the unit disk lifted to the hemisphere)."""
    r = np.sqrt(u1)
    phi = 2.0 * math.pi * u2
    z = np.sqrt(np.maximum(1.0 - u1, 0.0))
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=-1)


def reach_in_unit_disk(b0: np.ndarray, e: np.ndarray) -> np.ndarray:
    """Distance from points b0 (..., 2) of the unit disk of direction cosines to the unit
    circle along unit vectors e (..., 2), broadcast: the root t >= 0 of |b0 + t e| = 1, written
    without cancellation (s / (a + sqrt(a^2 + s)) where a = e.b0 > 0, s = 1 - |b0|^2)."""
    along = np.sum(b0 * e, axis=-1)
    rest = np.maximum(1.0 - np.sum(b0 * b0, axis=-1), 0.0)
    root = np.sqrt(along * along + rest)
    outward = along > 0
    return np.where(outward, rest / np.where(outward, along + root, 1.0), root - along)


class ReflectionFamily:
    """Base of the opaque families: only pairs with both directions above the surface scatter.

    A subclass names its `family` and `PARAMETERS` and gives the pair formulas _eval, _pdf and
    _sample_directions over flat (n, 3) arrays of unit directions above the horizon."""

    family = ""
    PARAMETERS: tuple[Parameter, ...] = ()
    #: Names of the fixed settings the constructor takes beside the parameters (attributes).
    SETTINGS: tuple[str, ...] = ()

    def __init__(self, **values):
        for p in self.PARAMETERS:
            setattr(self, p.name, p.check(values[p.name]))

    @classmethod
    def from_parameters(cls, values: Mapping[str, float], **settings) -> ReflectionFamily:
        """The model for parameter values by name (what a fit reports), with the family's
        fixed settings (a distribution, a masking form) as keywords; every name must be one of
        PARAMETERS and every parameter given, else a ValueError naming them."""
        names = {p.name for p in cls.PARAMETERS}
        unknown, missing = sorted(set(values) - names), sorted(names - set(values))
        if unknown or missing:
            raise ValueError(f"{cls.family} takes parameters {sorted(names)}; unknown "
                             f"{unknown}, missing {missing}")
        extra = sorted(set(settings) - set(cls.SETTINGS))
        if extra:
            raise ValueError(f"{cls.family} takes settings {list(cls.SETTINGS)}, not {extra}")
        return cls(**values, **settings)

    def parameters(self) -> dict[str, float]:
        """The parameter values by name, in PARAMETERS order."""
        return {p.name: getattr(self, p.name) for p in self.PARAMETERS}

    def settings(self) -> dict:
        """The fixed settings by name, in SETTINGS order."""
        return {name: getattr(self, name) for name in self.SETTINGS}

    def __repr__(self) -> str:
        values = ", ".join(f"{k}={v!r}" for k, v in {**self.parameters(),
                                                      **self.settings()}.items())
        return f"{type(self).__name__}({values})"

    # --- public contract (as the microfacet models) -------------------------------------------

    def eval(self, wi, wo) -> np.ndarray:
        """BSDF value f(wi, wo) in 1/sr, no cosine factor; wi, wo (..., 3) broadcast."""
        return self._over_live_pairs(wi, wo, self._eval)

    def pdf(self, wi, wo) -> np.ndarray:
        """Density over solid angle of wo of the directions sample() returns (valid ones)."""
        return self._over_live_pairs(wi, wo, self._pdf)

    def sample(self, wi, u):
        """(wo, weight, pdf) from uniforms u (..., 3) in [0, 1); weight = f |cos o| / pdf.

        A failed sample (wi or the drawn direction at or below the horizon) has wo = 0,
        weight 0 and pdf 0."""
        u = np.asarray(u, dtype=np.float64)
        if u.ndim == 0 or u.shape[-1] != 3:
            raise ValueError(f"u must have shape (..., 3), got {u.shape}")
        (wi,) = direction_arrays(wi)
        full = np.broadcast_shapes(wi.shape, u.shape)
        shape = full[:-1]
        wi = unit(np.broadcast_to(wi, full).reshape(-1, 3))
        u = np.broadcast_to(u, full).reshape(-1, 3)
        up = wi[:, 2] > COS_HORIZON
        wi = np.where(up[:, None], wi, [0.0, 0.0, 1.0])  # below the surface: fails below
        wo = self._sample_directions(wi, u)
        ok = up & (wo[:, 2] > COS_HORIZON)
        pdf = np.zeros(len(wo))
        weight = np.zeros(len(wo))
        if ok.any():
            wi_ok, wo_ok = wi[ok], wo[ok]
            pdf[ok] = self._pdf(wi_ok, wo_ok)
            with np.errstate(divide="ignore", invalid="ignore"):
                weight[ok] = self._eval(wi_ok, wo_ok) * wo_ok[:, 2] / pdf[ok]
        ok &= pdf > 0
        return (np.where(ok[:, None], wo, 0.0).reshape(shape + (3,)),
                np.where(ok, weight, 0.0).reshape(shape), np.where(ok, pdf, 0.0).reshape(shape))

    # --- shared pieces ----------------------------------------------------------------------

    @staticmethod
    def _over_live_pairs(wi, wo, value) -> np.ndarray:
        """value(wi, wo) at the pairs with both directions above the horizon, 0 at the
        others; the result has the broadcast shape of wi and wo without the last axis."""
        wi, wo = directions(wi, wo)
        shape = wi.shape[:-1]
        wi, wo = wi.reshape(-1, 3), wo.reshape(-1, 3)
        live = (wi[:, 2] > COS_HORIZON) & (wo[:, 2] > COS_HORIZON)
        if live.all():  # no copies of the live pairs
            return value(wi, wo).reshape(shape)
        out = np.zeros(len(wi))
        if live.any():
            out[live] = value(wi[live], wo[live])
        return out.reshape(shape)

    def _eval(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def _pdf(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        """Cosine-weighted hemisphere density (the diffuse families' sampler)."""
        return wo[:, 2] / math.pi

    def _sample_directions(self, wi: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Directions drawn for wi (flat, above the horizon) from uniforms u; the base draws
        the cosine-weighted hemisphere from u1, u2."""
        return cosine_hemisphere(u[:, 0], u[:, 1])
