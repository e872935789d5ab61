"""Mitsuba export of a multiple-scattering fit: directional albedo R, T that Mitsuba 3 itself
samples, single-scattering material (baseline) vs the gonio_multiscatter plugin, against gonio.

For Walter's ground glass (GGX alpha 0.394) and acid-etched glass (GGX 0.553), eta 1.51,
separable masking, fitted with multiple scattering: gonio's model R and T
(calibration.exports.mitsuba_energy.model_albedo: the model's own sample() for single
scattering, the random walk for orders >= 2, energy_loss for their sum), then the export
written with --single-scattering ("before", the baseline) and as the plugin ("after"), each
loaded by Mitsuba's parser and sampled SAMPLES times per incidence by its bsdf.sample
(llvm_ad_rgb, importance mode; tests/fitting/mitsuba_albedo.py). "sum/gonio" is the material's
R + T over the model's. Also the time the export takes (the plugin's tables).
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
             "theta  gonio R   gonio T | before R  before T  sum/gonio | after R   after T   "
             "sum/gonio"]
    for k, theta in enumerate(REPORT_ANGLES_DEG):
        r, t = model.outside[0][k], model.outside[1][k]
        b_r, b_t, _ = mitsuba_albedo(before, theta, SAMPLES)
        a_r, a_t, err = mitsuba_albedo(after, theta, SAMPLES)
        lines.append(f"{theta:5g}  {r:7.4f}  {t:7.4f} | {b_r:7.4f}  {b_t:7.4f}  "
                     f"{(b_r + b_t) / (r + t):9.4f} | {a_r:7.4f}  {a_t:7.4f}  "
                     f"{(a_r + a_t) / (r + t):9.4f}")
    lines.append(f"(Mitsuba: {SAMPLES} samples per incidence, standard error of R + T "
                 f"{err:.1g})")
    return lines


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        for name, alpha in GLASSES:
            print("\n".join(table(name, alpha, Path(tmp))))


if __name__ == "__main__":
    main()
