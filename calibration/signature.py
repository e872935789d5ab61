"""The instrument signature: what the bench alone adds to the sample readings.

Signature readings (kind "signature": the sample retracted, the arm, elevation and azimuth where
sample readings go; gonio/plan.py) are dark-subtracted per range and divided by the beam power
at their time: the share of the beam that reaches the detector without a sample. Averaged per
arm position and interpolated linearly in arm angle (within one elevation, never extrapolated)
to each sample reading, that share times the beam power at the reading is the power the bench
adds to it, with a sigma from the signature readings' noise (the dark noise of their range,
shot noise) and their dark level's. Per sample point reduction then gets

- the noise-equivalent BSDF: the signature's BSDF equivalent (its power over the reading's
  scale Phi Omega factor |cos o|) and the dark-noise floor's (one reading's dark noise on the
  point's range over that scale), in ReducedData.meta["signature"];
- the flag "signature" where the signature's magnitude (it is negative where the arm's stray
  light is weaker than at the dark position) exceeds `share` (default 10 %) of the net signal;
  left in, such a point is biased by more than that share, so unless the signature is
  subtracted it is not valid;
- when asked (`subtract`), the net signal less the signature, its variance added to the noise.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calibration.beam import BeamPower
from calibration.dark import DarkModel
from calibration.values import CalibrationError

DEFAULT_SHARE = 0.1  # flag points whose signature exceeds this share of the net signal
FLAG = "signature"


@dataclass(frozen=True)
class SignatureOutcome:
    """What the signature does to the sample readings: their net signal and noise (W, with the
    signature subtracted when asked), flags, points to leave out, and the report for meta."""

    net_w: np.ndarray
    noise_w: np.ndarray
    flags: np.ndarray  # (N,) str: FLAG where the signature exceeds the share, else ""
    invalid: np.ndarray  # (N,) bool: flagged and not subtracted
    meta: dict | None  # None: the run has no signature readings


def bench_share(signature: np.ndarray, dark: DarkModel, beam: BeamPower, shot_per_w: float
                ) -> tuple[np.ndarray, np.ndarray]:
    """(share of the beam, its sigma) of each signature reading: dark-subtracted power over the
    beam power at its time; sigma from the dark noise of its range, shot noise and the dark
    level's uncertainty."""
    level, level_sigma, noise = dark.at(signature["range_w"])
    net = signature["power_w"] - level
    noise = np.sqrt(noise**2 + shot_per_w * np.maximum(net, 0.0))
    phi, _ = beam.smooth_at(signature["t_s"])
    return net / phi, np.hypot(noise, level_sigma) / phi


def interpolate(arm: np.ndarray, value: np.ndarray, sigma: np.ndarray, at: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
    """Inverse-variance mean of the values at each distinct arm angle, linearly interpolated to
    `at` with the sigmas propagated; NaN outside the span (never extrapolated)."""
    key = np.round(arm, 6)
    arms, group = np.unique(key, return_inverse=True)
    w = 1.0 / sigma**2
    w_sum = np.bincount(group, w)
    mean = np.bincount(group, w * value) / w_sum
    mean_sigma = 1.0 / np.sqrt(w_sum)
    at = np.round(at, 6)
    if len(arms) == 1:
        hit = at == arms[0]
        return np.where(hit, mean[0], np.nan), np.where(hit, mean_sigma[0], np.nan)
    k = np.clip(np.searchsorted(arms, at), 1, len(arms) - 1)
    u = (at - arms[k - 1]) / (arms[k] - arms[k - 1])
    inside = (u >= 0.0) & (u <= 1.0)
    out = (1.0 - u) * mean[k - 1] + u * mean[k]
    out_sigma = np.hypot((1.0 - u) * mean_sigma[k - 1], u * mean_sigma[k])
    return np.where(inside, out, np.nan), np.where(inside, out_sigma, np.nan)


def bench_power(signature: np.ndarray, rows: np.ndarray, dark: DarkModel, beam: BeamPower,
                shot_per_w: float) -> tuple[np.ndarray, np.ndarray]:
    """(power, sigma) in W the bench adds to each sample reading (NaN where no signature
    reading at its elevation brackets its arm angle)."""
    share, share_sigma = bench_share(signature, dark, beam, shot_per_w)
    power, sigma = np.full(len(rows), np.nan), np.full(len(rows), np.nan)
    elevation = np.round(signature["elevation_deg"], 6)
    for e in np.unique(elevation):
        mine = elevation == e
        at = np.round(rows["elevation_deg"], 6) == e
        power[at], sigma[at] = interpolate(signature["arm_deg"][mine], share[mine],
                                           share_sigma[mine], rows["arm_deg"][at])
    phi, _ = beam.smooth_at(rows["t_s"])
    return power * phi, sigma * phi


def apply_signature(readings: np.ndarray, rows: np.ndarray, dark: DarkModel, beam: BeamPower,
                    shot_per_w: float, net_w: np.ndarray, noise_w: np.ndarray,
                    scale: np.ndarray, share: float = DEFAULT_SHARE, subtract: bool = False
                    ) -> SignatureOutcome:
    """The signature of a run's readings applied to its sample rows (net signal net_w, noise
    noise_w, reduction scale Phi Omega factor |cos o|): flags, and the subtraction if asked."""
    if not 0.0 < share < 1.0:
        raise CalibrationError(f"signature share must be in (0, 1), got {share!r}")
    signature = readings[(readings["kind"] == FLAG) & ~readings["saturated"]]
    none = np.zeros(len(rows), bool)
    if len(signature) == 0:
        if subtract:
            raise CalibrationError("cannot subtract the signature: the run has no unsaturated "
                                   "signature readings (add [signature] to the plan and a "
                                   "[signature] position to the instrument config)")
        return SignatureOutcome(net_w, noise_w, np.full(len(rows), ""), none, None)
    power, sigma = bench_power(signature, rows, dark, beam, shot_per_w)
    covered = np.isfinite(power)
    flagged = covered & (np.abs(power) > share * np.abs(net_w))
    if subtract:
        net_w = np.where(covered, net_w - power, net_w)
        noise_w = np.where(covered, np.hypot(noise_w, sigma), noise_w)
    with np.errstate(divide="ignore", invalid="ignore"):
        nebsdf, nebsdf_sigma = power / scale, sigma / scale
        floor = dark.at(rows["range_w"])[2] / scale
    meta = {
        "readings": int(len(signature)), "share": share, "subtracted": subtract,
        "flagged": int(flagged.sum()), "uncovered": int((~covered).sum()),
        "bsdf_per_sr": _listed(nebsdf), "sigma_per_sr": _listed(nebsdf_sigma),
        "dark_floor_per_sr": _listed(floor), "ranges": _per_range(rows["range_w"], nebsdf, floor),
    }
    return SignatureOutcome(net_w, noise_w, np.where(flagged, FLAG, ""),
                            flagged & (not subtract), meta)


def _per_range(range_w: np.ndarray, nebsdf: np.ndarray, floor: np.ndarray) -> dict:
    """Per detector range: points, the dark floor's NEBSDF (min, median) and the signature's
    (median, max over the covered points), 1/sr."""
    out = {}
    for r in np.unique(range_w):
        on = (range_w == r) & np.isfinite(floor)
        sig = nebsdf[on & np.isfinite(nebsdf)]
        out[f"{r:.6g}"] = {
            "points": int(on.sum()),
            "dark_floor_min_per_sr": float(floor[on].min()) if on.any() else None,
            "dark_floor_median_per_sr": float(np.median(floor[on])) if on.any() else None,
            "signature_median_per_sr": float(np.median(sig)) if len(sig) else None,
            "signature_max_per_sr": float(sig.max()) if len(sig) else None,
        }
    return out


def _listed(values: np.ndarray) -> list[float | None]:
    """Values for JSON: None where not finite."""
    return [float(v) if np.isfinite(v) else None for v in values]


def summary(meta: dict) -> list[str]:
    """Lines for `gonio reduce`: what was done with the signature, and the NEBSDF per range."""
    verb = "subtracted" if meta["subtracted"] else "not subtracted"
    lines = [f"signature: {meta['readings']} readings, {verb}; {meta['flagged']} points where it "
             f"exceeds {meta['share']:.0%} of the net signal"
             + ("" if meta["subtracted"] or not meta["flagged"]
                else " (left out; --subtract-signature keeps them)")
             + (f"; {meta['uncovered']} points outside its arm span" if meta["uncovered"]
                else "")]
    lines.append(f"  {'range W':>9} {'points':>6} {'dark floor 1/sr':>16} "
                 f"{'signature 1/sr (median, max)':>30}")
    for r, row in meta["ranges"].items():
        floor = _show(row["dark_floor_median_per_sr"])
        sig = (f"{_show(row['signature_median_per_sr'])}, "
               f"{_show(row['signature_max_per_sr'])}")
        lines.append(f"  {r:>9} {row['points']:>6} {floor:>16} {sig:>30}")
    return lines


def _show(value: float | None) -> str:
    return "-" if value is None else f"{value:.3g}"
