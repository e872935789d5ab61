"""second_order's error and CPU per target at its default nodes, graded cells against the old rule.

Cases: Beckmann and GGX, alpha 0.1, 0.3, 0.6, 1.0, incidence 0, 30, 60, 85 deg; glass eta 1.51
lit from air and from inside (the incidence mirrored below), and a conductor (n = 0.2 + 3.4i).
Targets every 10 deg of theta_o at azimuths 0-180 deg in 45-deg steps; errors relative, over
targets above 1e-3 of the case's peak, against the old rule at 36x its nodes (432 polar, 324
azimuth per radian; it agrees with 72x to 1e-7 and with the new rule at 36x to 4e-7 at the
worst pairs). The old rule is second_order_kernel.py at BASELINE_COMMIT (cells cut only at
support edges, planes and kink cones, 12 polar and 9 azimuth nodes per radian), loaded from git
in the same run. Prints, per distribution and alpha, the worst error of both over the three
media per incidence, the median CPU ms per target of both, and the load average.
Usage: python bench/second_order_accuracy.py [--quick]   (--quick: alpha 0.1 and 0.3, 30 and
85 deg)
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "bench")]

from _git_baseline import module_at  # noqa: E402

from model.bsdf import RoughConductor, RoughDielectric  # noqa: E402
from model.bsdf.multiple_scattering import (  # noqa: E402
    RandomWalkBSDF,
    nee_kernel,
    second_order_kernel,
)
from model.bsdf.multiple_scattering import second_order as so  # noqa: E402
from model.bsdf.multiple_scattering.energy import gauss_legendre_unit  # noqa: E402

BASELINE_COMMIT = "59155da"
KERNEL_PATH = "model/bsdf/multiple_scattering/second_order_kernel.py"
OLD_NODES = (12, 9)
REFERENCE_SCALE = 36
DISTRIBUTIONS = ("beckmann", "ggx")
ALPHAS = (0.1, 0.3, 0.6, 1.0)
INCIDENCES_DEG = (0.0, 30.0, 60.0, 85.0)
MEDIA = ("glass from air", "glass from inside", "conductor")
FLOOR = 1e-3
LABELS = {"beckmann": "Beckmann", "ggx": "GGX"}


def direction(theta_deg: float, phi_deg: float = 0.0) -> np.ndarray:
    t, p = np.radians(theta_deg), np.radians(phi_deg)
    return np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])


TARGETS = np.array([direction(t, p) for t in range(0, 181, 10) for p in range(0, 181, 45)])


def walker(distribution: str, alpha: float, medium: str):
    model = (RoughConductor(distribution, alpha, eta_complex=0.2 + 3.4j, masking="correlated")
             if medium == "conductor" else
             RoughDielectric(distribution, alpha, 1.51, masking="correlated"))
    return RandomWalkBSDF(model, guided=False).walker


def order_two(kernel, walk, wi: np.ndarray, polar: float, azimuth: float) -> np.ndarray:
    """second_order's compiled route towards TARGETS with the given kernel module."""
    walk, wi, targets = so._lit_from_above(walk, wi, TARGETS)
    xs, ws = so._rules(so.MAX_CELL_NODES)
    hx, hw = gauss_legendre_unit(so.HEIGHT_NODES)
    a0 = -float(walk.slopes.signed_lambda(-wi[None, :])[0])
    out = np.empty(len(targets))
    kernel.second_order_all(nee_kernel.surface(walk.slopes, walk.micro), wi, a0,
                            np.ascontiguousarray(targets), float(polar), float(azimuth), xs, ws,
                            hx, hw, out)
    return out


def timed(kernel, walk, wi, polar, azimuth) -> tuple[np.ndarray, float]:
    """(values, CPU ms per target) of one call towards every target."""
    start = time.process_time()
    values = order_two(kernel, walk, wi, polar, azimuth)
    return values, 1e3 * (time.process_time() - start) / len(TARGETS)


def main(quick: bool) -> None:
    old = module_at(BASELINE_COMMIT, KERNEL_PATH, "second_order_kernel_baseline")
    alphas, incidences = ((0.1, 0.3), (30.0, 85.0)) if quick else (ALPHAS, INCIDENCES_DEG)
    print("load average {:.2f} {:.2f} {:.2f} (1, 5, 15 min)".format(*os.getloadavg()))
    print(f"reference: the old rule at {REFERENCE_SCALE}x its nodes; old rule: {KERNEL_PATH} at "
          f"{BASELINE_COMMIT} ({OLD_NODES[0]}, {OLD_NODES[1]} per radian); new: defaults "
          f"({so.POLAR_NODES}, {so.AZIMUTH_NODES}); worst relative error over targets >= "
          f"{FLOOR:g} of the peak, three media")
    print("| slopes, alpha | " + " | ".join(f"{i:.0f} deg new / old" for i in incidences)
          + " | ms/target new | old |")
    print("|---|" + "---|" * (len(incidences) + 2))
    worst = (0.0, None)
    for distribution in DISTRIBUTIONS:
        for alpha in alphas:
            cells, ms_new, ms_old = [], [], []
            for incidence in incidences:
                errors = [0.0, 0.0]
                for medium in MEDIA:
                    walk = walker(distribution, alpha, medium)
                    wi = direction(180.0 - incidence if medium == "glass from inside"
                                   else incidence)
                    reference = order_two(old, walk, wi, OLD_NODES[0] * REFERENCE_SCALE,
                                          OLD_NODES[1] * REFERENCE_SCALE)
                    keep = reference > FLOOR * reference.max()
                    order_two(second_order_kernel, walk, wi, 12, 9)  # compiled before timing
                    new, ms = timed(second_order_kernel, walk, wi, so.POLAR_NODES,
                                    so.AZIMUTH_NODES)
                    base, ms_b = timed(old, walk, wi, *OLD_NODES)
                    ms_new.append(ms)
                    ms_old.append(ms_b)
                    for k, values in enumerate((new, base)):
                        errors[k] = max(errors[k], np.abs(values[keep] / reference[keep] - 1).max())
                    if errors[0] > worst[0]:
                        worst = (errors[0], (distribution, alpha, incidence, medium))
                cells.append(f"{errors[0]:.1e} / {errors[1]:.1e}")
            print(f"| {LABELS[distribution]} {alpha} | " + " | ".join(cells)
                  + f" | {np.median(ms_new):.2f} | {np.median(ms_old):.2f} |", flush=True)
    print(f"new rule's worst: {worst[0]:.1e} at {worst[1]}")
    print("load average {:.2f} {:.2f} {:.2f} (1, 5, 15 min)".format(*os.getloadavg()))


if __name__ == "__main__":
    main("--quick" in sys.argv[1:])
