"""Error and time per call of the fit's model of a reading across a lobe edge.

The fit's forward model of a reading (calibration.smearing) across a lobe edge: error against
the emulated bench's own noiseless aperture integral, and time per call.

Walter's ground glass (GGX 0.394, n 1.51; aperture 0.57 deg, beam 0.03 deg) at incidence 30
deg, in-plane across the end of the transmitted lobe (theta_o ~ 55.5 deg), where GGX jumps to
zero on the vertical facets. "split": Smearing with the model's edge circles (split along them,
as the bench does); baseline in the same run: the same Smearing with the edges hidden (the
rule before: rim probe, then 40 polar rings on the straddling points). The bench reference is
sim.bench at rtol 1e-8. Times: fastest of 5 calls on the whole Walter in-plane scan (532
points at 0/30/60/75 deg), as a fit repeats them (the split rule is built on the first call
for those pairs and kept); the first call is printed too. Last, the forward model's time over
that of the compiled kernel calls inside it (the fit's floor), fastest of 20 calls, in wall time
and in CPU time (the kernels run on two threads: a loaded machine stretches their wall time).
Run: python bench/smearing_edges.py
"""

from __future__ import annotations

import os
import time

import numpy as np
from _seeds import DETERMINISTIC

from calibration.fit import build_model
from calibration.smearing import Smearing, smearing_order
from gonio.geometry import directions
from model.bsdf import kernels
from sim.bench.config import build_bench

ALPHA, ETA, APERTURE_MM, DISTANCE_MM, DIVERGENCE_DEG = 0.394, 1.51, 10.0, 500.0, 0.03


class EdgesHidden:
    """The model with only eval: Smearing cannot know its edges (the rule before the split)."""

    def __init__(self, model):
        self.model = model

    def eval(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        return self.model.eval(wi, wo)


def pairs(theta_i: np.ndarray, arms: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sample-frame (wi, wo) arrays for the in-plane stage positions."""
    ds = [directions(t, a) for t, a in zip(theta_i, arms, strict=True)]
    return np.array([d[0] for d in ds]), np.array([d[1] for d in ds])


def fastest(job, repeats: int = 5) -> float:
    """Fastest wall time (s) of `repeats` calls: the machine is shared."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        job()
        times.append(time.perf_counter() - t0)
    return min(times)


class KernelClock:
    """Wall and CPU seconds and pairs spent in the compiled dielectric kernel
    (model.bsdf.kernels.dielectric, which the models look up at each call) while installed: the
    forward model's floor."""

    def __init__(self):
        self.seconds, self.cpu_seconds, self.pairs = 0.0, 0.0, 0

    def __enter__(self):
        self.inner = kernels.dielectric

        def timed(wi, wo, *args):
            t0, c0 = time.perf_counter(), time.process_time()
            out = self.inner(wi, wo, *args)
            self.seconds += time.perf_counter() - t0
            self.cpu_seconds += time.process_time() - c0
            self.pairs += len(wi)
            return out

        kernels.dielectric = timed
        return self

    def __exit__(self, *exc) -> None:
        kernels.dielectric = self.inner


def forward_over_kernel(job, repeats: int = 5) -> tuple[float, float, int, float]:
    """(seconds of job, seconds of its kernel calls, pairs, CPU seconds of job over those of
    its kernel calls) of the fastest of `repeats` calls, and that CPU ratio's smallest."""
    runs, cpu_ratios = [], []
    for _ in range(repeats):
        with KernelClock() as clock:
            t0, c0 = time.perf_counter(), time.process_time()
            job()
            runs.append((time.perf_counter() - t0, clock.seconds, clock.pairs))
            cpu_ratios.append((time.process_time() - c0) / clock.cpu_seconds)
    return (*min(runs), min(cpu_ratios))


def main() -> None:
    half_angle = np.arctan(0.5 * APERTURE_MM / DISTANCE_MM)
    beta = float(np.degrees(half_angle))
    optics = Smearing(beta, smearing_order(beta, ALPHA), DIVERGENCE_DEG,
                      smearing_order(DIVERGENCE_DEG, ALPHA))
    model = build_model("ggx", ALPHA, ETA, "separable")
    bench = build_bench({
        "source": {"power_w": 1.0, "divergence_deg": DIVERGENCE_DEG},
        "sample": {"kind": "hemisphere", "distribution": "ggx", "alpha": ALPHA, "eta": ETA,
                   "multiple_scattering": False, "diffraction": False},
        "aperture": {"diameter_mm": APERTURE_MM, "distance_mm": DISTANCE_MM, "rtol": 1e-8}})
    omega = 4 * np.pi * np.sin(0.5 * half_angle) ** 2
    t_exit = 1 - ((ETA - 1) / (ETA + 1)) ** 2

    arms = np.arange(153.5, 156.51, 0.125)
    wi, wo = pairs(np.full(len(arms), 30.0), arms)
    power = np.array([bench.power_w({"sample": 30.0, "arm": a, "azimuth": 0.0,
                                     "elevation": 0.0}) for a in arms])
    reference = power / (np.abs(wo[:, 2]) * omega * t_exit)
    peak = reference.max()
    split = optics.average(model, wi, wo)
    hidden = optics.average(EdgesHidden(model), wi, wo)

    scan_i = np.repeat([0.0, 30.0, 60.0, 75.0], 136)
    scan_arm = np.tile(np.arange(95.0, 265.0, 1.25), 4)
    keep = np.abs(scan_arm - 180.0 - scan_i) > 2.0  # the arm cannot look into the source
    swi, swo = pairs(scan_i[keep], scan_arm[keep])
    t_first = fastest(lambda: optics.average(model, swi, swo), repeats=1)  # builds the rule
    t_split = fastest(lambda: optics.average(model, swi, swo))
    t_hidden = fastest(lambda: optics.average(EdgesHidden(model), swi, swo))
    t_model, t_kernel, kernel_pairs, cpu_ratio = forward_over_kernel(
        lambda: optics.average(model, swi, swo), repeats=20)

    print(f"load average {os.getloadavg()[0]:.2f} (2 cores, shared)")
    print(f"{DETERMINISTIC}; quadrature")
    print(f"{optics}")
    print(f"{'rule':<34}{'max |err| / peak':>18}{'max rel err':>13}{'ms / call':>11}")
    lit = reference > 1e-3 * peak
    for name, values, seconds in (("split along edge circles", split, t_split),
                                  ("baseline: rim probe + 40 rings", hidden, t_hidden)):
        err = np.abs(values - reference)
        print(f"{name:<34}{err.max() / peak:>18.2e}{(err[lit] / reference[lit]).max():>13.2e}"
              f"{1e3 * seconds:>11.2f}")
    print(f"(errors over {len(arms)} readings across the edge at theta_i 30 deg; times over "
          f"{len(swi)} in-plane points, repeated on the same pairs as in a fit; the split's "
          f"first call, which builds its rule, {1e3 * t_first:.1f} ms)")
    print(f"the fit's forward model (split rule) {1e3 * t_model:.2f} ms per call, its kernel "
          f"evaluations ({kernel_pairs} pairs) {1e3 * t_kernel:.2f} ms of it: "
          f"{t_model / t_kernel:.2f}x its kernel evaluations ({cpu_ratio:.2f}x in CPU time)")


if __name__ == "__main__":
    main()
