"""Mitsuba export of a multiple-scattering fit: directional albedo R, T that Mitsuba 3 itself
samples, single-scattering material (baseline) vs the gonio_multiscatter plugin, against gonio.

For Walter's ground glass (GGX alpha 0.394) and acid-etched glass (GGX 0.553), eta 1.51,
separable masking, fitted with multiple scattering: gonio's model R and T
(calibration.exports.mitsuba_energy.model_albedo: the model's own sample() for single
scattering, the random walk for orders >= 2, energy_loss for their sum), then the export
written with --single-scattering ("before", the baseline) and as the plugin ("after"), each
loaded by Mitsuba's parser and sampled SAMPLES times per incidence by its bsdf.sample
(llvm_ad_rgb, importance mode; tests/fitting/mitsuba_albedo.py) from each of SEEDS seeds.
"sum/gonio" is the material's R + T over the model's, the median [min, max] over the seeds (R
and T the medians); gonio's R + T has no random draw (a fixed Sobol set and energy_loss). Also
the time the export takes (the plugin's tables).
Run: python bench/mitsuba_albedo.py
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "tests" / "fitting")]

from _seeds import SEEDS, median_range  # noqa: E402
from mitsuba_albedo import load_material, mitsuba_albedo  # noqa: E402

from calibration.exports.mitsuba_energy import REPORT_ANGLES_DEG, model_albedo  # noqa: E402
from calibration.exports.model import mitsuba_files  # noqa: E402
from calibration.fit import FitResult  # noqa: E402

SAMPLES = 1 << 20
GLASSES = (("ground glass", 0.394), ("acid-etched", 0.553))


def glass_fit(alpha: float) -> FitResult:
    """A GGX glass fit (eta 1.51, separable masking) that used multiple scattering."""
    return FitResult(distribution="ggx", masking="separable", names=("alpha",),
                     values=np.array([alpha]), errors=np.array([0.0]), covariance=np.zeros((1, 1)),
                     eta=1.51, k=None, chi2_dof_fit=1.0, n_fit=1, chi2_dof_heldout=None,
                     n_heldout=0, preferred_by=None, walks=64)


def over_seeds(material, theta: float, gonio_sum: float) -> tuple[str, float]:
    """'R  T  sum/gonio' of the material at theta over SEEDS seeds (R, T the medians; sum/gonio
    the median [min, max]), and the median standard error of its R + T."""
    runs = np.array([mitsuba_albedo(material, theta, SAMPLES, seed) for seed in range(SEEDS)])
    r, t = np.median(runs[:, 0]), np.median(runs[:, 1])
    ratio = median_range((runs[:, 0] + runs[:, 1]) / gonio_sum, ".4f")
    return f"{r:7.4f}  {t:7.4f}  {ratio:>24}", float(np.median(runs[:, 2]))


def table(name: str, alpha: float, out: Path) -> list[str]:
    """The comparison lines of one glass."""
    result = glass_fit(alpha)
    model = model_albedo(result, np.array(REPORT_ANGLES_DEG))
    before = load_material(mitsuba_files(result, out / "single.xml", single_scattering=True)[0][0])
    start = time.perf_counter()
    after_path = mitsuba_files(result, out / "plugin.xml")[0][0]
    export_s = time.perf_counter() - start
    after = load_material(after_path)
    lines = [f"{name}, GGX alpha {alpha:g}, eta 1.51 (export with the plugin: {export_s:.1f} s)",
             f"theta  gonio R   gonio T | before R  before T  {'sum/gonio':>24} | after R   "
             f"after T   {'sum/gonio':>24}"]
    for k, theta in enumerate(REPORT_ANGLES_DEG):
        r, t = model.outside[0][k], model.outside[1][k]
        shown_before, _ = over_seeds(before, theta, r + t)
        shown_after, err = over_seeds(after, theta, r + t)
        lines.append(f"{theta:5g}  {r:7.4f}  {t:7.4f} |  {shown_before} |  {shown_after}")
    lines.append(f"(Mitsuba: {SAMPLES} samples per incidence and seed, {SEEDS} seeds; standard "
                 f"error of one seed's R + T {err:.1g})")
    return lines


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        for name, alpha in GLASSES:
            print("\n".join(table(name, alpha, Path(tmp))))


if __name__ == "__main__":
    main()
