"""Evaluations per second of the microfacet BSDF, beside a plain-numpy baseline.

Throughput of the microfacet BSDF: RoughDielectric (GGX, alpha 0.3, eta 1.51) on 1,000,000
random direction pairs, evaluations per second, beside a plain-numpy baseline in the same run.

Rows: a straightforward textbook numpy eval (the baseline; no grazing, TIR or eta ~ 1 care),
the model's numpy reference path, its compiled numba kernels (all threads, and one thread) for
eval, pdf() and sample() (separable masking, and sample() with height-correlated masking,
whose transmission G2 is a Beta function), and sample() of two other models. Median of several
runs; compile time is excluded (warm-up). The machine is shared, so the CPU-time rate (items per
CPU second, all threads summed) is printed beside the wall-clock one (median and best run): it is
the per-core cost, free of time spent descheduled; the load average is printed before and after.
For scale, the issue quotes Mitsuba 3's LLVM backend at ~100 M pairs/s (float32, 2 cores)."""

from __future__ import annotations

import os
import time

import numpy as np

from model.bsdf import RoughConductor, RoughDielectric
from model.bsdf.kernels import AVAILABLE

N = 1_000_000
ALPHA, ETA = 0.3, 1.51
MITSUBA_LLVM = 100e6


def textbook_ggx_eval(wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """Walter 2007 GGX rough dielectric as one would first write it in numpy (the baseline)."""
    a2 = ALPHA * ALPHA
    ci, co = wi[:, 2], wo[:, 2]
    refl = ci * co > 0
    eta_i = np.where(ci > 0, 1.0, ETA)
    eta_o = np.where(ci > 0, ETA, 1.0)
    h = np.where(refl[:, None], wi + wo, -(eta_i[:, None] * wi + eta_o[:, None] * wo))
    h /= np.linalg.norm(h, axis=1, keepdims=True)
    h *= np.sign(h[:, 2:3])
    ih, oh = np.sum(wi * h, 1), np.sum(wo * h, 1)
    cos2 = h[:, 2] ** 2
    d = a2 / (np.pi * (cos2 * (a2 - 1) + 1) ** 2)
    g1 = [2 / (1 + np.sqrt(1 + a2 * (1 - c * c) / (c * c))) for c in (ci, co)]
    rel = eta_o / eta_i
    g = np.sqrt(np.maximum(rel * rel - 1 + ih * ih, 0))
    c = np.abs(ih)
    f = 0.5 * (g - c) ** 2 / (g + c) ** 2 * (1 + (c * (g + c) - 1) ** 2 / (c * (g - c) + 1) ** 2)
    f = np.where(rel * rel - 1 + ih * ih < 0, 1.0, f)
    dg = d * g1[0] * g1[1]
    fr = f * dg / (4 * np.abs(ci * co))
    ft = (np.abs(ih * oh / (ci * co)) * eta_o**2 * (1 - f) * dg / (eta_i * ih + eta_o * oh) ** 2)
    return np.where(refl, fr, ft)


def model_arguments(model) -> dict:
    """Constructor arguments of a bench model, to rebuild it on the numpy backend."""
    d = model.distribution
    common = dict(distribution=d.name, alpha=float(d.alpha_x), masking=model.masking,
                  sampling=model.sampling)
    if isinstance(model, RoughConductor):
        return dict(common, eta_complex=model.eta_complex)
    return dict(common, eta=model.eta)


def rate(fn, repeats: int) -> tuple[float, float, float]:
    """Items per wall-clock second (median and best run) and per CPU second (median, all
    threads) of fn(). On a shared machine the best run is the one least descheduled."""
    wall, cpu = [], []
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        fn()
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    return N / float(np.median(wall)), N / min(wall), N / float(np.median(cpu))


def main() -> None:
    rng = np.random.default_rng(0)
    wi, wo = rng.normal(size=(2, N, 3))
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    u = rng.random((N, 3))
    reference = RoughDielectric("ggx", ALPHA, ETA, backend="numpy")
    load_before = os.getloadavg()[0]
    rows = [("plain numpy (textbook) eval, baseline", rate(lambda: textbook_ggx_eval(wi, wo), 5)),
            ("gonio numpy reference eval", rate(lambda: reference.eval(wi, wo), 5)),
            ("gonio numpy reference sample", rate(lambda: reference.sample(wi, u), 3))]
    if AVAILABLE:
        import numba

        fast = RoughDielectric("ggx", ALPHA, ETA)
        fast.eval(wi[:10], wo[:10])  # compile (or load from cache) outside the timing
        fast.pdf(wi[:10], wo[:10])
        threads = numba.get_num_threads()
        fast.sample(wi[:10], u[:10])
        rows.append((f"gonio numba eval ({threads} threads)", rate(lambda: fast.eval(wi, wo), 15)))
        rows.append((f"gonio numba pdf ({threads} threads)", rate(lambda: fast.pdf(wi, wo), 8)))
        rows.append((f"gonio numba sample ({threads} threads)",
                     rate(lambda: fast.sample(wi, u), 8)))
        corr = RoughDielectric("ggx", ALPHA, ETA, masking="correlated")
        corr.sample(wi[:10], u[:10])
        rows.append((f"  correlated masking ({threads} threads)",
                     rate(lambda: corr.sample(wi, u), 8)))
        numba.set_num_threads(1)
        rows.append(("gonio numba eval (1 thread)", rate(lambda: fast.eval(wi, wo), 15)))
        rows.append(("gonio numba pdf (1 thread)", rate(lambda: fast.pdf(wi, wo), 8)))
        rows.append(("gonio numba sample (1 thread)", rate(lambda: fast.sample(wi, u), 8)))
        rows.append(("  correlated masking (1 thread)", rate(lambda: corr.sample(wi, u), 8)))
        numba.set_num_threads(threads)
        for name, model in (("Beckmann walter", RoughDielectric("beckmann", ALPHA, ETA,
                                                                 sampling="walter")),
                            ("conductor GGX", RoughConductor("ggx", ALPHA, 0.2 + 3.1j))):
            model.sample(wi[:10], u[:10])
            slow = type(model)(**model_arguments(model), backend="numpy")
            rows.append((f"{name} sample, numpy", rate(lambda m=slow: m.sample(wi, u), 3)))
            rows.append((f"{name} sample, numba ({threads} thr)",
                         rate(lambda m=model: m.sample(wi, u), 5)))
    base = rows[0][1][0]
    print(f"RoughDielectric GGX alpha={ALPHA} eta={ETA}, {N:,} random pairs, float64; "
          f"load average {load_before:.1f} before, {os.getloadavg()[0]:.1f} after, on "
          f"{os.cpu_count()} cores")
    print(f"{'':40s} {'wall M/s':>9s} {'best':>6s} {'x base':>7s} {'x Mitsuba':>9s} "
          f"{'per CPU-s':>10s}")
    for name, (wall, best, cpu) in rows:
        print(f"{name:40s} {wall / 1e6:9.1f} {best / 1e6:6.1f} {wall / base:7.2f} "
              f"{wall / MITSUBA_LLVM:9.2f} {cpu / 1e6:10.1f}")
    print("wall = median run, best = fastest run (least descheduled), per CPU-s = median CPU "
          "time of all threads; x base and x Mitsuba use the median")
    print("baseline = plain numpy textbook eval in this run; Mitsuba 3 LLVM ~100 M/s (float32, "
          "2 cores) as quoted in the issue, not measured here")


if __name__ == "__main__":
    main()
