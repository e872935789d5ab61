"""energy_loss against an independent integral: in and out of glass, mirrors, grazing, small alpha.

Cases: eta 1.51 (light from air), 1/1.51 (light inside glass), None (mirror, F = 1); alpha 1e-3,
1e-2, 0.1, 0.5, 1.0; theta 0, 45, 85, 89 deg; Beckmann and GGX; correlated masking. The
reference is tests/bsdf_ms/energy_reference.py (nested adaptive scipy quadrature over the
normal's spherical angles, its own D, Lambda and Fresnel). The baseline is the quadrature
energy.py had at BASELINE_COMMIT (fixed 32 azimuths, no split at total internal reflection),
loaded from git in the same run. Prints, per medium and distribution, the worst relative error
over the losses >= FLOOR (and the worst absolute error below it), where each quadrature's worst
case lies, the median CPU milliseconds per call of both, and the load average.
Usage: python bench/energy_loss_accuracy.py [--quick]
"""

from __future__ import annotations

import os
import sys
import time
import warnings
from pathlib import Path

import numpy as np
from _seeds import DETERMINISTIC
from scipy import integrate

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "tests" / "bsdf_ms"), str(ROOT / "bench")]

from _git_baseline import module_at  # noqa: E402
from energy_reference import loss  # noqa: E402

from model.bsdf.multiple_scattering import energy_loss  # noqa: E402

BASELINE_COMMIT = "8c02327"
ENERGY_PATH = "model/bsdf/multiple_scattering/energy.py"
MEDIA = {"eta 1.51": 1.51, "eta 1/1.51": 1.0 / 1.51, "mirror": None}
ALPHAS = (1e-3, 1e-2, 0.1, 0.5, 1.0)
THETAS_DEG = (0.0, 45.0, 85.0, 89.0)
DISTRIBUTIONS = ("beckmann", "ggx")
FLOOR = 1e-7


def baseline_energy_loss():
    """energy_loss of BASELINE_COMMIT's energy.py, imported from git beside the current one."""
    return module_at(BASELINE_COMMIT, ENERGY_PATH, "energy_baseline").energy_loss


def timed(function, *args) -> tuple[float, float]:
    """(value, CPU seconds) of one call."""
    start = time.process_time()
    value = function(*args)
    return value, time.process_time() - start


def error(value: float, reference: float) -> tuple[float, bool]:
    """(relative error if the loss is >= FLOOR else absolute error, whether relative)."""
    if reference >= FLOOR:
        return abs(value / reference - 1.0), True
    return abs(value - reference), False


def block_row(label: str, rows: list[tuple]) -> str:
    """One table row: the worst errors of both quadratures over a block's cases."""
    def worst(index: int, relative: bool) -> str:
        found = [r[index][0] for r in rows if r[index][1] == relative]
        return f"{max(found):.1e}" if found else "-"

    def worst_case(index: int) -> str:
        return max(rows, key=lambda r: r[index][0] if r[index][1] else 0.0)[2]

    ms_new = 1e3 * np.median([r[3] for r in rows])
    ms_old = 1e3 * np.median([r[4] for r in rows])
    return (f"| {label} | {worst(0, True)} | {worst(1, True)} | {worst(0, False)} | "
            f"{worst(1, False)} | {worst_case(0)} | {worst_case(1)} | {ms_new:.0f} | "
            f"{ms_old:.0f} |")


def main() -> None:
    quick = "--quick" in sys.argv
    alphas = (1e-3, 1.0) if quick else ALPHAS
    thetas = (45.0, 89.0) if quick else THETAS_DEG
    warnings.simplefilter("ignore", integrate.IntegrationWarning)  # the reference's own
    baseline = baseline_energy_loss()
    print("load average {:.2f} {:.2f} {:.2f} (1, 5, 15 min)".format(*os.getloadavg()))
    print(f"{DETERMINISTIC}; quadratures, gonio's and the reference's")
    print(f"reference: tests/bsdf_ms/energy_reference.py; baseline: energy.py at "
          f"{BASELINE_COMMIT}; relative errors over losses >= {FLOOR:g}, absolute below")
    print("| block | rel. err. | baseline | abs. err. (< 1e-7) | baseline | worst at "
          "(alpha, theta) | baseline's worst at | ms/call | baseline ms |")
    print("|---|---|---|---|---|---|---|---|---|")
    for medium, eta in MEDIA.items():
        for name in DISTRIBUTIONS:
            rows = []
            for alpha in alphas:
                for theta_deg in thetas:
                    theta = np.radians(theta_deg)
                    reference = loss(name, alpha, eta, theta)
                    value, seconds = timed(energy_loss, name, alpha, eta, theta)
                    old, old_seconds = timed(baseline, name, alpha, eta, theta)
                    rows.append((error(value, reference), error(old, reference),
                                 f"{alpha:g}, {theta_deg:g}", seconds, old_seconds))
            print(block_row(f"{medium} {name}", rows))
    theta = np.radians(89.0)
    print(f"Beckmann 1.0, eta 1/1.51, 89 deg: energy_loss "
          f"{energy_loss('beckmann', 1.0, 1.0 / 1.51, theta):.6f}, baseline "
          f"{baseline('beckmann', 1.0, 1.0 / 1.51, theta):.6f}, reference "
          f"{loss('beckmann', 1.0, 1.0 / 1.51, theta):.6f}")
    print("load average {:.2f} {:.2f} {:.2f} (1, 5, 15 min)".format(*os.getloadavg()))


if __name__ == "__main__":
    main()
