"""Synthetic reduced data straight from the model with a realistic noise law, for testing fits
and for bench/fit_time.py without running a bench: relative noise plus an absolute floor set by
the dynamic range (six decades by default), in Walter's in-plane geometry."""

from __future__ import annotations

import math

import numpy as np

from calibration.fit import build_model
from calibration.reduced import ReducedData
from calibration.smearing import aperture_average


def in_plane_directions(theta_i_deg: float, eta: float, alpha: float, n_uniform: int = 36,
                        n_peak: int = 24, sides: tuple[str, ...] = ("reflection", "transmission")
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(wi, wo, transmission) for one incidence: a uniform sweep of the outgoing angle on each
    side plus a dense patch across the specular / refracted peak (width from alpha)."""
    ti = math.radians(theta_i_deg)
    wi = np.array([-math.sin(ti), 0.0, math.cos(ti)])
    blocks = []
    for side in sides:
        peak = ti if side == "reflection" else math.asin(math.sin(ti) / eta)
        half = min(4.0 * alpha, math.radians(60.0))
        theta = np.concatenate([np.radians(np.linspace(-87.5, 87.5, n_uniform)),
                                np.linspace(peak - half, peak + half, n_peak)])
        theta = theta[np.abs(theta) < math.radians(89.0)]
        sign = 1.0 if side == "reflection" else -1.0
        wo = np.stack([np.sin(theta), np.zeros_like(theta), sign * np.cos(theta)], axis=1)
        blocks.append((wo, np.full(len(theta), side == "transmission")))
    wo = np.concatenate([b[0] for b in blocks])
    return np.broadcast_to(wi, wo.shape).copy(), wo, np.concatenate([b[1] for b in blocks])


def synthesize(distribution: str, alpha: float, eta: float = 1.51,
               incidences_deg: tuple[float, ...] = (0.0, 30.0, 60.0, 75.0),
               relative_noise: float = 0.02, dynamic_range: float = 1e6, seed: int = 0,
               masking: str = "separable", n_uniform: int = 36, n_peak: int = 24,
               sides: tuple[str, ...] = ("reflection", "transmission"),
               aperture_half_angle_deg: float = 0.0) -> ReducedData:
    """ReducedData drawn from the model: sigma = relative_noise * f + peak / dynamic_range,
    Gaussian noise with that sigma; points below the floor stay valid (they carry the floor).
    With an aperture, f is the model averaged over it (a converged order-16 cap rule)."""
    model = build_model(distribution, alpha, eta, masking)
    meta = {"eta": eta, "aperture_half_angle_deg": aperture_half_angle_deg,
            "synthetic": {"distribution": distribution, "alpha": alpha, "masking": masking,
                          "seed": seed}}
    return drawn(model, [in_plane_directions(t, eta, alpha, n_uniform, n_peak, sides)
                         for t in incidences_deg], relative_noise, dynamic_range, seed, meta,
                 aperture_half_angle_deg=aperture_half_angle_deg)


def synthesize_family(family: str, values: dict[str, float], settings: dict | None = None,
                      incidences_deg: tuple[float, ...] = (0.0, 30.0, 60.0),
                      relative_noise: float = 0.02, dynamic_range: float = 1e6,
                      seed: int = 0, scale: float = 1.0, eta: float = 1.5,
                      lobe_alpha: float = 0.2, n_uniform: int = 36, n_peak: int = 24
                      ) -> ReducedData:
    """ReducedData of a model family (model.bsdf.families) in reflection, drawn as synthesize
    draws them, times `scale` (data known up to a scale); `eta` is the sample's nominal index
    the data carry, `lobe_alpha` sizes the patch of points across the specular peak."""
    from model.bsdf.families import make_family

    model = make_family(family, values, **(settings or {}))
    meta = {"eta": eta, "aperture_half_angle_deg": 0.0,
            "synthetic": {"family": family, **values, "scale": scale, "seed": seed}}
    return drawn(model, [in_plane_directions(t, eta, lobe_alpha, n_uniform, n_peak,
                                             ("reflection",)) for t in incidences_deg],
                 relative_noise, dynamic_range, seed, meta, scale)


def drawn(model, parts: list[tuple[np.ndarray, np.ndarray, np.ndarray]],
          relative_noise: float, dynamic_range: float, seed: int, meta: dict,
          scale: float = 1.0, aperture_half_angle_deg: float = 0.0) -> ReducedData:
    """ReducedData of `scale` times the model at the (wi, wo, transmission) parts: sigma =
    relative_noise * f + peak / dynamic_range, Gaussian noise with that sigma."""
    wi, wo, transmission = (np.concatenate([p[k] for p in parts]) for k in range(3))
    f = scale * aperture_average(model, wi, wo, aperture_half_angle_deg, 16)
    sigma = relative_noise * f + f.max() / dynamic_range
    rng = np.random.default_rng(seed)
    measured = f + sigma * rng.standard_normal(len(f))
    return ReducedData(wi, wo, measured, sigma, np.ones(len(f), bool), transmission, meta)
