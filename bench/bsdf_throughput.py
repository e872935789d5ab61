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
With Mitsuba 3 installed (`gonio[mitsuba]`), its own roughdielectric (same GGX alpha and eta,
llvm_ad_rgb variant, float32) evaluates, pdfs and samples the same pairs in a child process of
the same run (an LLVM backend Dr.Jit cannot use aborts the process), and each gonio row is
divided by Mitsuba's row of the same operation and thread count; without it that column says so."""

from __future__ import annotations

import importlib.metadata
import importlib.util
import os
import subprocess
import sys
import time

import numpy as np

from model.bsdf import RoughConductor, RoughDielectric
from model.bsdf.kernels import AVAILABLE

N = 1_000_000
ALPHA, ETA = 0.3, 1.51
MITSUBA_VARIANT = "llvm_ad_rgb"
MITSUBA_FLAG = "--mitsuba"
Rates = tuple[float, float, float]


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


def rate(fn, repeats: int) -> Rates:
    """Items per wall-clock second (median and best run) and per CPU second (median, all
    threads) of fn(). On a shared machine the best run is the one least descheduled."""
    wall, cpu = [], []
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        fn()
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    return N / float(np.median(wall)), N / min(wall), N / float(np.median(cpu))


def directions() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The bench's random direction pairs (wi, wo) and sample uniforms, the same in every
    process of a run."""
    rng = np.random.default_rng(0)
    wi, wo = rng.normal(size=(2, N, 3))
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    return wi, wo, rng.random((N, 3))


def measure_mitsuba() -> None:
    """Print Mitsuba 3's roughdielectric rates on the bench's pairs, one tab-separated line per
    (operation, threads); run in a child process by mitsuba_rates()."""
    import drjit as dr
    import mitsuba as mi

    mi.set_variant(MITSUBA_VARIANT)
    bsdf = mi.load_dict({"type": "roughdielectric", "distribution": "ggx", "alpha": ALPHA,
                         "int_ior": ETA, "ext_ior": 1.0})
    wi, wo, u = (a.T.astype(np.float32) for a in directions())
    si = dr.zeros(mi.SurfaceInteraction3f, N)
    si.wi = mi.Vector3f(wi)
    si.sh_frame = mi.Frame3f(mi.Vector3f(0.0, 0.0, 1.0))
    out, ctx = mi.Vector3f(wo), mi.BSDFContext()
    u1, u2 = mi.Float(u[0]), mi.Point2f(u[1:])
    dr.eval(si, out, u1, u2)
    operations = {"eval": lambda: bsdf.eval(ctx, si, out), "pdf": lambda: bsdf.pdf(ctx, si, out),
                  "sample": lambda: bsdf.sample(ctx, si, u1, u2)}

    def evaluated(operation):
        """Run one operation and wait for its kernel (the LLVM backend runs it asynchronously)."""
        dr.eval(operation())
        dr.sync_thread()

    for threads in (dr.thread_count(), 1):
        dr.set_thread_count(threads)
        for name, operation in operations.items():
            evaluated(operation)  # compile (or load from Dr.Jit's cache) outside the timing
            wall, best, cpu = rate(lambda op=operation: evaluated(op), 31)
            print(f"{name}\t{threads}\t{wall}\t{best}\t{cpu}")


def mitsuba_rates() -> tuple[dict[tuple[str, int], Rates], str]:
    """Mitsuba 3's rates by (operation, threads), measured in a child process, and a line
    saying what was measured or why nothing was."""
    if importlib.util.find_spec("mitsuba") is None:
        return {}, "Mitsuba 3 not installed (gonio[mitsuba]): its column was not measured"
    done = subprocess.run([sys.executable, __file__, MITSUBA_FLAG], capture_output=True,
                          text=True)
    rates = {}
    for line in done.stdout.splitlines():
        name, threads, *values = line.split("\t")
        rates[name, int(threads)] = tuple(map(float, values))
    if done.returncode != 0 or not rates:
        lines = done.stderr.strip().splitlines() or [f"exit status {done.returncode}"]
        reason = next((line for line in lines if "error" in line.lower()), lines[-1])
        return {}, (f"Mitsuba 3 {MITSUBA_VARIANT} failed ({reason[:120]}): its column was not "
                    "measured")
    return rates, (f"Mitsuba 3 {importlib.metadata.version('mitsuba')} roughdielectric GGX, "
                   f"{MITSUBA_VARIANT} "
                   "(float32), the same pairs, measured in this run (a child process; "
                   "results left in Dr.Jit arrays)")


def main() -> None:
    wi, wo, u = directions()
    reference = RoughDielectric("ggx", ALPHA, ETA, backend="numpy")
    load_before = os.getloadavg()[0]
    rows = [("plain numpy (textbook) eval, baseline", None,
             rate(lambda: textbook_ggx_eval(wi, wo), 5)),
            ("gonio numpy reference eval", None, rate(lambda: reference.eval(wi, wo), 5)),
            ("gonio numpy reference sample", None, rate(lambda: reference.sample(wi, u), 3))]
    if AVAILABLE:
        import numba

        fast = RoughDielectric("ggx", ALPHA, ETA)
        fast.eval(wi[:10], wo[:10])  # compile (or load from cache) outside the timing
        fast.pdf(wi[:10], wo[:10])
        fast.sample(wi[:10], u[:10])
        corr = RoughDielectric("ggx", ALPHA, ETA, masking="correlated")
        corr.sample(wi[:10], u[:10])
        all_threads = numba.get_num_threads()
        for threads in (all_threads, 1):
            numba.set_num_threads(threads)
            label = f"{threads} thread{'s' if threads > 1 else ''}"
            rows.append((f"gonio numba eval ({label})", ("eval", threads),
                         rate(lambda: fast.eval(wi, wo), 15)))
            rows.append((f"gonio numba pdf ({label})", ("pdf", threads),
                         rate(lambda: fast.pdf(wi, wo), 8)))
            rows.append((f"gonio numba sample ({label})", ("sample", threads),
                         rate(lambda: fast.sample(wi, u), 8)))
            rows.append((f"  correlated masking ({label})", None,
                         rate(lambda: corr.sample(wi, u), 8)))
        numba.set_num_threads(all_threads)
        for name, model in (("Beckmann walter", RoughDielectric("beckmann", ALPHA, ETA,
                                                                 sampling="walter")),
                            ("conductor GGX", RoughConductor("ggx", ALPHA, 0.2 + 3.1j))):
            model.sample(wi[:10], u[:10])
            slow = type(model)(**model_arguments(model), backend="numpy")
            rows.append((f"{name} sample, numpy", None, rate(lambda m=slow: m.sample(wi, u), 3)))
            rows.append((f"{name} sample, numba ({all_threads} thr)", None,
                         rate(lambda m=model: m.sample(wi, u), 5)))
    load_gonio = os.getloadavg()[0]
    mitsuba, mitsuba_note = mitsuba_rates()
    for (name, threads), rates in mitsuba.items():
        label = f"{threads} thread{'s' if threads > 1 else ''}"
        rows.append((f"Mitsuba 3 {name} ({label})", (name, threads), rates))
    base = rows[0][2][0]
    print(f"RoughDielectric GGX alpha={ALPHA} eta={ETA}, {N:,} random pairs, float64; "
          f"load average {load_before:.1f} before, {load_gonio:.1f} after gonio's rows, "
          f"{os.getloadavg()[0]:.1f} after, on {os.cpu_count()} cores")
    print(f"{'':40s} {'wall M/s':>9s} {'best':>6s} {'x base':>7s} {'x Mitsuba':>9s} "
          f"{'per CPU-s':>10s}")
    for name, key, (wall, best, cpu) in rows:
        versus = f"{wall / mitsuba[key][0]:9.2f}" if key in mitsuba else f"{'-':>9s}"
        print(f"{name:40s} {wall / 1e6:9.1f} {best / 1e6:6.1f} {wall / base:7.2f} {versus} "
              f"{cpu / 1e6:10.1f}")
    print("wall = median run, best = fastest run (least descheduled), per CPU-s = median CPU "
          "time of all threads; x base and x Mitsuba use the median; x Mitsuba divides by "
          "Mitsuba's row of the same operation and threads")
    print(f"baseline = plain numpy textbook eval in this run; {mitsuba_note}")


if __name__ == "__main__":
    if MITSUBA_FLAG in sys.argv[1:]:
        measure_mitsuba()
    else:
        main()
