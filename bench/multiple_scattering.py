"""Multiple scattering (Heitz 2016 random walk): walk throughput, order 2 by quadrature, and the
public sample() beside Heitz et al.'s C++ walk.

Walks per CPU-second of the compiled walk (eval, sample, shared paths; GGX and Beckmann, glass
and mirror, alpha 0.3 and 1.0) beside the numpy walk measured in the same run as the baseline
and against issue 19's C++ figures for this machine and the C++ walk as measured here once
(CPP_MEASURED); the two-scale diffraction model's evals per second beside the plain microfacet
eval; order 2 by quadrature (second_order) per table column, CPU time and error, beside the
numpy route it replaced (second_order_reference), same run; and the public sample() (pdf
included) per CPU-second beside Heitz et al.'s C++ walk built from its published source and run
case by case alternately with it in the same run (sample_table; --cpp-source DIR or
GONIO_HEITZ_SOURCE names the source, _heitz_cpp.py builds it; without it the stored figures
CPP_SAMPLE_STORED stand in, labelled so). The walk's error against walks over seeds is
bench/ms_walk_error.py.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from model.bsdf import RoughConductor, RoughDielectric
from model.bsdf.diffraction import KCorrelationPSD, TwoScaleDiffraction
from model.bsdf.multiple_scattering import (
    Microsurface,
    RandomWalkBSDF,
)
from model.bsdf.multiple_scattering.second_order import second_order, second_order_reference
from model.bsdf.multiple_scattering.walk import Walker

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _heitz_cpp as heitz_cpp  # noqa: E402  (beside this script)

ETA = 1.51
ALPHAS = (0.3, 1.0)


def direction(theta_deg: float, phi_deg: float = 0.0) -> np.ndarray:
    """Unit vector at polar angle theta and azimuth phi (degrees)."""
    t, p = np.radians(theta_deg), np.radians(phi_deg)
    return np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])


def direction_pairs(incidences=(0.0, 30.0, 60.0),
                    outgoing=((20.0, 180.0), (45.0, 90.0), (150.0, 0.0), (170.0, 180.0))
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Every incidence (deg, in the x-z plane) with every outgoing (theta, phi) in deg; by
    default 12 pairs: incidence 0, 30, 60 deg; reflection and transmission, in and out of
    plane."""
    wi = [direction(ti) for ti in incidences for _ in outgoing]
    wo = [direction(to, po) for _ in incidences for to, po in outgoing]
    return np.array(wi), np.array(wo)


def timed(fn, *args, **kwargs):
    """(result, seconds) of one call."""
    start = time.perf_counter()
    out = fn(*args, **kwargs)
    return out, time.perf_counter() - start


#: Issue 19's single-thread figures for Heitz et al.'s C++ random walk on this machine, walks per
#: CPU-second: GGX glass at alpha 0.3-1.0 (eval, sample), and the range for the other cases.
CPP_GGX_GLASS = {"eval": 1.3e6, "sample": 1.2e6}
CPP_OTHER = (0.7e6, 1.4e6)
#: Heitz et al.'s published C++ walk (MicrosurfaceScattering.cpp, g++ -O2, float, Gaussian
#: heights, 60 deg incidence, wo uniform on the sphere or the upper hemisphere for a mirror),
#: measured on this machine on 2026-12-02: median of 3 runs of 1e6 walks each, alternating
#: with this walk (docs/performance.md, "Heitz et al.'s C++ walk, paired runs"); not rebuilt by
#: this script.
CPP_MEASURED = {("ggx", "dielectric", 0.3): (1.224e6, 1.539e6),
                ("ggx", "dielectric", 1.0): (8.125e5, 1.062e6),
                ("ggx", "conductor", 0.3): (1.123e6, 1.559e6),
                ("ggx", "conductor", 1.0): (7.754e5, 1.047e6),
                ("beckmann", "dielectric", 0.3): (7.515e5, 9.723e5),
                ("beckmann", "dielectric", 1.0): (6.499e5, 8.149e5),
                ("beckmann", "conductor", 0.3): (7.489e5, 9.904e5),
                ("beckmann", "conductor", 1.0): (5.620e5, 8.084e5)}
SURFACES = [(name, kind, alpha) for name in ("ggx", "beckmann") for kind in ("dielectric",
                                                                              "conductor")
            for alpha in ALPHAS]
TARGETS = 64


def _walk_modes(walker, n: int, rng: np.random.Generator) -> dict[str, float]:
    """Walks per CPU-second, and scattering events per walk, of eval (forced hits and
    roulette, NEE towards one wo per walk), sample (the analog walk) and the shared-path
    estimator (orders >= 2 towards TARGETS directions per walk), from 60 deg incidence towards
    uniform wo on the sphere (the upper hemisphere for a mirror)."""
    wi = np.tile(direction(60.0), (n, 1))
    u = rng.random((n, 2))
    z = 2.0 * u[:, 0] - 1.0
    if walker.micro.transmits is False:
        z = np.abs(z)
    r = np.sqrt(1.0 - z * z)
    wo = np.stack([r * np.cos(2 * np.pi * u[:, 1]), r * np.sin(2 * np.pi * u[:, 1]), z], -1)
    shared = max(n // 8, 1)
    rates, events = {}, {}
    for mode, args, kwargs in (("eval", (wi, rng, wo), {}), ("sample", (wi, rng), {}),
                               ("shared", (wi[:shared], rng),
                                {"targets": wo[:TARGETS], "min_order": 2})):
        start = time.process_time()
        res = walker.run(*args, **kwargs)
        rates[mode] = len(args[0]) / (time.process_time() - start)
        events[mode] = float(res.orders.mean())
    return rates, events


EFFICIENCY_WALKS = 20000


def _eval_efficiency(walker, rng: np.random.Generator) -> float:
    """CPU milliseconds per direction pair for a 1 % relative error of the eval walk at the
    eval table's 12 pairs (reflection pairs only on a mirror): mean over the pairs of the
    relative variance per walk times the CPU time per walk, over 1e-4. It is the same for any
    walk count, so it weighs a walk's cost against its noise (the walks' efficiency)."""
    wi, wo = direction_pairs()
    if walker.micro.transmits is False:
        wi, wo = wi[wo[:, 2] > 0.0], wo[wo[:, 2] > 0.0]
    start = time.process_time()
    res = walker.run(np.repeat(wi, EFFICIENCY_WALKS, axis=0), rng,
                     np.repeat(wo, EFFICIENCY_WALKS, axis=0))
    per_walk = (time.process_time() - start) / res.value.size
    v = res.value.reshape(len(wi), EFFICIENCY_WALKS)
    mean = v.mean(axis=1)
    lit = mean > 0.0
    return 1e3 * float(np.mean(v[lit].var(axis=1) / mean[lit] ** 2)) * per_walk / 1e-4


def throughput_table(rng: np.random.Generator) -> list[str]:
    """Walks per CPU-second of the compiled walk beside the numpy walk (the per-walk baseline,
    same run), and the ratio to issue 19's C++ figures (GGX glass: eval 1.3e6, sample 1.2e6;
    other cases 0.7-1.4e6, so two ratios: against 0.7e6 / against 1.4e6) and to the C++ walk
    as measured on this machine for each case (CPP_MEASURED). events: scattering
    events per walk (an eval walk is forced to hit, so it is longer than the analog walk the
    C++ eval follows, and carries less variance); ms@1%: the eval walk's efficiency
    (_eval_efficiency: CPU ms per pair for 1 % relative error at the 12 pairs)."""
    lines = [f"walks per CPU-second, 60 deg incidence: compiled walk vs numpy walk (baseline, same "
             f"run); shared = orders >= 2 towards {TARGETS} targets per walk; vs C++: ratio to "
             f"issue 19's figures for Heitz's C++ walk on this machine, and to that walk as "
             f"measured here on 2026-12-02 (CPP_MEASURED; neither run by this script)",
             f"{'surface':>20} {'mode':>7} {'events':>6} {'compiled/s':>11} {'numpy/s':>10} "
             f"{'speed-up':>8} {'vs C++ (issue 19)':>18} {'measured':>8} {'ms@1%':>7}"]
    for name, kind, alpha in SURFACES:
        model = RandomWalkBSDF(Microsurface(name, alpha, kind, eta=ETA), walks=1)
        slopes, micro, guided = model.slopes, model.micro, model.guided
        _walk_modes(Walker(slopes, micro, guided), 64, rng)  # compile (or load the cache)
        fast, events = _walk_modes(Walker(slopes, micro, guided), 40000, rng)
        slow, _ = _walk_modes(Walker(slopes, micro, guided, compiled=False), 10000, rng)
        efficiency = f"{_eval_efficiency(Walker(slopes, micro, guided), rng):7.3f}"
        label = f"{name} {'glass' if kind == 'dielectric' else 'mirror'} {alpha}"
        for mode in ("eval", "sample", "shared"):
            if name == "ggx" and kind == "dielectric" and mode in CPP_GGX_GLASS:
                versus = f"{fast[mode] / CPP_GGX_GLASS[mode]:18.2f}"
            elif mode == "shared":
                versus = f"{'(no C++ analogue)':>18}"
            else:
                versus = f"{fast[mode] / CPP_OTHER[0]:8.2f} / {fast[mode] / CPP_OTHER[1]:<7.2f}"
            measured = (f"{fast[mode] / CPP_MEASURED[name, kind, alpha][mode == 'sample']:8.2f}"
                        if mode != "shared" else f"{'':8}")
            lines.append(f"{label:>20} {mode:>7} {events[mode]:6.2f} {fast[mode]:11.3e} "
                         f"{slow[mode]:10.3e} {fast[mode] / slow[mode]:8.1f} {versus} {measured}"
                         f"{' ' + efficiency if mode == 'eval' else ''}")
    return lines


def diffraction_table(rng: np.random.Generator) -> list[str]:
    """Two-scale diffraction evals per second beside the plain microfacet eval (baseline)."""
    lines = ["diffraction (Holzschuch-Pacanowski, 256-point lobe integral) vs microfacet eval",
             f"{'pairs':>6} {'diffraction evals/s':>20} {'microfacet evals/s':>19}"]
    mf = RoughConductor("ggx", 0.2, 0.2 + 3.4j, masking="correlated")
    model = TwoScaleDiffraction(mf, KCorrelationPSD(30e-9, 2e-6, 2.0))
    n = 2000
    z = rng.random(n)
    phi = 2 * np.pi * rng.random(n)
    r = np.sqrt(1 - z * z)
    wo = np.stack([r * np.cos(phi), r * np.sin(phi), z], -1)
    wi = np.broadcast_to(direction(30.0), wo.shape)
    _, t_d = timed(model.eval, wi, wo, 633e-9)
    _, t_m = timed(mf.eval, wi, wo)
    lines.append(f"{n:6d} {n / t_d:20.3e} {n / t_m:19.3e}")
    return lines


#: A bench table column at the examples' 2.5 deg polar step: 37 polar angles of wo, one
#: hemisphere, one azimuth from the plane of incidence.
COLUMN_POLAR_DEG = np.linspace(0.0, 90.0, 37)
#: second_order's truth for the error columns: its own rule at 4x the nodes per radian.
FINE_POLAR, FINE_AZIMUTH = 48, 36


def _cpu(fn, *args, repeats: int = 3, **kwargs):
    """(result, CPU seconds) of a call: the least of `repeats` (the machine is shared)."""
    best = np.inf
    for _ in range(repeats):
        start = time.process_time()
        out = fn(*args, **kwargs)
        best = min(best, time.process_time() - start)
    return out, best


def _relative_error(value: np.ndarray, truth: np.ndarray) -> str:
    """Median and largest |value / truth - 1| over targets not dark (truth above 1e-6 of the
    column's peak), formatted."""
    lit = truth > 1e-6 * truth.max()
    err = np.abs(value[lit] / truth[lit] - 1.0)
    return f"{np.median(err):8.1e} {err.max():8.1e}"


def second_order_table(rng: np.random.Generator) -> list[str]:
    """Order 2 by quadrature per bench table column (37 polar angles of one hemisphere, at
    azimuth 0 and 45 deg from the plane of incidence), GGX 0.394 glass eta 1.51 lit at 0, 30,
    60 deg and from below (150 deg): CPU time and relative error (median, largest; over targets
    above 1e-6 of the column's peak) against the compiled rule at 4x its nodes, of the
    compiled route and of the numpy route it replaced (128 x 128, the baseline), same run."""
    glass = RoughDielectric("ggx", 0.394, ETA, masking="correlated")
    walker = RandomWalkBSDF(glass, guided=False).walker
    second_order(walker, direction(30.0), direction(40.0)[None, :])  # compile (or load)
    lines = ["order 2 by quadrature per bench column (37 wo, one hemisphere; GGX 0.394 glass): "
             "compiled vs numpy route (baseline, same run); error vs the compiled rule at 4x "
             "its nodes",
             f"{'incidence':>9} {'column':>14} {'compiled ms':>11} {'med err':>8} "
             f"{'max err':>8} {'numpy ms':>9} {'med err':>8} {'max err':>8} {'speed-up':>8}"]
    for theta_i in (0.0, 30.0, 60.0, 150.0):
        wi = direction(theta_i)
        for phi in (0.0, 45.0):
            for lower in (False, True):
                polar = 180.0 - COLUMN_POLAR_DEG if lower else COLUMN_POLAR_DEG
                targets = np.array([direction(t, phi) for t in polar])
                truth = second_order(walker, wi, targets, polar=FINE_POLAR, azimuth=FINE_AZIMUTH)
                fast, t_fast = _cpu(second_order, walker, wi, targets)
                slow, t_slow = _cpu(second_order_reference, walker, wi, targets)
                column = f"{'T' if lower else 'R'} phi {phi:2.0f} deg"
                lines.append(f"{theta_i:9.0f} {column:>14} {1e3 * t_fast:11.1f} "
                             f"{_relative_error(fast, truth)} {1e3 * t_slow:9.1f} "
                             f"{_relative_error(slow, truth)} {t_slow / t_fast:8.1f}")
    return lines


SAMPLE_INCIDENCES_DEG = (0.0, 30.0, 60.0, 85.0)
SAMPLE_ALPHAS = (0.1, 0.3, 1.0)
#: Paired runs per case: the C++ walk, then gonio's sample(), alternately.
PAIRED_RUNS = 3
CPP_WALKS = 400_000
GONIO_SAMPLES = 200_000
#: Heitz et al.'s C++ sample walk (g++ 12 -O2, Gaussian heights, eta 1.51 or an F = 1
#: conductor), walks per CPU-second, median of PAIRED_RUNS runs per case, measured by
#: sample_table on this machine on 2026-12-07: what the ratios are taken against when the
#: source is not given (labelled "stored").
CPP_SAMPLE_STORED: dict[tuple[str, str, float, float], float] = {
    ("ggx", "dielectric", 0.1, 0.0): 5.057e+06, ("ggx", "dielectric", 0.1, 30.0): 3.715e+06,
    ("ggx", "dielectric", 0.1, 60.0): 3.485e+06, ("ggx", "dielectric", 0.1, 85.0): 3.018e+06,
    ("ggx", "dielectric", 0.3, 0.0): 4.943e+06, ("ggx", "dielectric", 0.3, 30.0): 3.702e+06,
    ("ggx", "dielectric", 0.3, 60.0): 3.265e+06, ("ggx", "dielectric", 0.3, 85.0): 2.752e+06,
    ("ggx", "dielectric", 1.0, 0.0): 4.314e+06, ("ggx", "dielectric", 1.0, 30.0): 3.008e+06,
    ("ggx", "dielectric", 1.0, 60.0): 2.166e+06, ("ggx", "dielectric", 1.0, 85.0): 1.404e+06,
    ("ggx", "conductor", 0.1, 0.0): 6.075e+06, ("ggx", "conductor", 0.1, 30.0): 4.185e+06,
    ("ggx", "conductor", 0.1, 60.0): 3.810e+06, ("ggx", "conductor", 0.1, 85.0): 3.372e+06,
    ("ggx", "conductor", 0.3, 0.0): 4.766e+06, ("ggx", "conductor", 0.3, 30.0): 3.569e+06,
    ("ggx", "conductor", 0.3, 60.0): 3.307e+06, ("ggx", "conductor", 0.3, 85.0): 3.477e+06,
    ("ggx", "conductor", 1.0, 0.0): 1.982e+06, ("ggx", "conductor", 1.0, 30.0): 1.840e+06,
    ("ggx", "conductor", 1.0, 60.0): 2.044e+06, ("ggx", "conductor", 1.0, 85.0): 3.026e+06,
    ("beckmann", "dielectric", 0.1, 0.0): 4.373e+06,
    ("beckmann", "dielectric", 0.1, 30.0): 1.928e+06,
    ("beckmann", "dielectric", 0.1, 60.0): 1.929e+06,
    ("beckmann", "dielectric", 0.1, 85.0): 1.610e+06,
    ("beckmann", "dielectric", 0.3, 0.0): 3.990e+06,
    ("beckmann", "dielectric", 0.3, 30.0): 2.058e+06,
    ("beckmann", "dielectric", 0.3, 60.0): 1.805e+06,
    ("beckmann", "dielectric", 0.3, 85.0): 1.624e+06,
    ("beckmann", "dielectric", 1.0, 0.0): 4.083e+06,
    ("beckmann", "dielectric", 1.0, 30.0): 1.767e+06,
    ("beckmann", "dielectric", 1.0, 60.0): 1.534e+06,
    ("beckmann", "dielectric", 1.0, 85.0): 1.165e+06,
    ("beckmann", "conductor", 0.1, 0.0): 4.665e+06,
    ("beckmann", "conductor", 0.1, 30.0): 2.124e+06,
    ("beckmann", "conductor", 0.1, 60.0): 2.118e+06,
    ("beckmann", "conductor", 0.1, 85.0): 1.716e+06,
    ("beckmann", "conductor", 0.3, 0.0): 5.073e+06,
    ("beckmann", "conductor", 0.3, 30.0): 2.093e+06,
    ("beckmann", "conductor", 0.3, 60.0): 1.746e+06,
    ("beckmann", "conductor", 0.3, 85.0): 1.678e+06,
    ("beckmann", "conductor", 1.0, 0.0): 1.818e+06,
    ("beckmann", "conductor", 1.0, 30.0): 1.225e+06,
    ("beckmann", "conductor", 1.0, 60.0): 1.402e+06,
    ("beckmann", "conductor", 1.0, 85.0): 1.685e+06}


def _public_model(name: str, kind: str, alpha: float):
    """The public model a renderer calls: RoughDielectric (eta ETA) or an F = 1 RoughConductor,
    height-correlated, with multiple scattering."""
    if kind == "dielectric":
        return RoughDielectric(name, alpha, ETA, masking="correlated", multiple_scattering=True)
    return RoughConductor(name, alpha, None, masking="correlated", multiple_scattering=True)


def _sample_rate(model, wi: np.ndarray, rng: np.random.Generator) -> tuple[float, np.ndarray]:
    """(samples per CPU-second of one sample() call over the rows of wi, pdf included; its wo)."""
    u = rng.random((len(wi), 3))
    start = time.process_time()
    wo, _, _ = model.sample(wi, u, rng)
    return len(wi) / (time.process_time() - start), wo


def sample_table(rng: np.random.Generator, cpp_binary: Path | None) -> list[str]:
    """The public sample() (wo, weight and its pdf) per CPU-second against Heitz's C++ sample
    walk, every case: GGX and Beckmann, glass (eta 1.51) and F = 1 mirror, alpha 0.1, 0.3, 1.0,
    incidence 0, 30, 60, 85 deg; PAIRED_RUNS pairs per case, C++ (CPP_WALKS walks) then gonio
    (one call over GONIO_SAMPLES directions), so load falls on both alike. ratio: gonio / C++
    per pair, least (min), median and largest; T: the share of wo below the surface, C++ and
    gonio (the same walk, so the same within ~0.002)."""
    source = ("C++ built from its published source in this run" if cpp_binary else
              "C++: STORED figures (CPP_SAMPLE_STORED; no --cpp-source DIR or "
              f"${heitz_cpp.SOURCE_ENV} given)")
    lines = [f"public sample() (pdf included) vs Heitz's C++ sample walk, per CPU-second, "
             f"{PAIRED_RUNS} paired runs per case; {source}",
             f"{'surface':>20} {'theta':>5} {'C++ walks/s':>11} {'gonio/s':>10} "
             f"{'ratio min':>9} {'median':>6} {'max':>6} {'T C++':>6} {'gonio':>6}"]
    ratios = []
    for name in ("ggx", "beckmann"):
        for kind in ("dielectric", "conductor"):
            for alpha in SAMPLE_ALPHAS:
                model = _public_model(name, kind, alpha)
                for theta in SAMPLE_INCIDENCES_DEG:
                    wi = np.tile(direction(theta), (GONIO_SAMPLES, 1))
                    _sample_rate(model, wi[:64], rng)  # compile (or load the cache)
                    cpp, ours, below = [], [], (np.nan, np.nan)
                    for _ in range(PAIRED_RUNS):
                        if cpp_binary is None:
                            cpp.append(CPP_SAMPLE_STORED.get((name, kind, alpha, theta), np.nan))
                        else:
                            rate, _, share = heitz_cpp.walks_per_cpu_second(
                                cpp_binary, name, kind, alpha, theta, "sample", CPP_WALKS)
                            cpp.append(rate)
                            below = (share, below[1])
                        rate, wo = _sample_rate(model, wi, rng)
                        ours.append(rate)
                        below = (below[0], float(np.mean(wo[:, 2] < 0.0)))
                    r = np.array(ours) / np.array(cpp)
                    ratios.append(r.min())
                    label = f"{name} {'glass' if kind == 'dielectric' else 'mirror'} {alpha}"
                    lines.append(f"{label:>20} {theta:5.0f} {np.median(cpp):11.3e} "
                                 f"{np.median(ours):10.3e} {r.min():9.2f} {np.median(r):6.2f} "
                                 f"{r.max():6.2f} {below[0]:6.3f} {below[1]:6.3f}")
    lines.append(f"least ratio (min over runs) {np.nanmin(ratios):.2f}, median over cases "
                 f"{np.nanmedian(ratios):.2f}, cases below 1: "
                 f"{int(np.sum(np.array(ratios) < 1.0))} of {len(ratios)}")
    return lines


TABLES = {"throughput": throughput_table, "diffraction": diffraction_table,
          "second_order": second_order_table, "sample": sample_table}


def main(argv: list[str] | None = None) -> None:
    """Print the tables (all, or those named by --table)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cpp-source", metavar="DIR",
                        help="folder with Heitz et al.'s MicrosurfaceScattering.cpp and .h "
                             f"(default: ${heitz_cpp.SOURCE_ENV}); built with g++ -O2")
    parser.add_argument("--table", action="append", choices=sorted(TABLES),
                        help="print only this table (repeatable)")
    args = parser.parse_args(argv)
    source = heitz_cpp.source_folder(args.cpp_source)
    binary = heitz_cpp.build(source) if source is not None else None
    rng = np.random.default_rng(2016)
    for name in args.table or TABLES:
        table = TABLES[name]
        print("\n".join(table(rng, binary) if table is sample_table else table(rng)))
        print()


if __name__ == "__main__":
    main()
