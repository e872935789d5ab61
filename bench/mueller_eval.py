"""Mueller BSDF evaluations per second beside the unpolarised eval, in one run.

eval_mueller() of RoughDielectric (GGX alpha 0.3, eta 1.51) and RoughConductor (GGX alpha 0.3,
gold at 633 nm, 0.18 + 3.43i) on bsdf_throughput's 1,000,000 random pairs, beside eval() on
the same pairs in the same process: default backend (numba when it imports) and the numpy
reference. Median of several runs, compile time excluded, the rate per CPU second beside the
wall-clock one (the machine is shared); then the multiple-scattering share that eval_mueller
adds to M00 as depolarised light, which bounds its error in every other element.

    python bench/mueller_eval.py"""

from __future__ import annotations

import os

import numpy as np
from bsdf_throughput import N, directions, rate

from model.bsdf import RoughConductor, RoughDielectric
from model.bsdf.multiple_scattering import energy_loss

#: Pairs of the numpy rows (the numpy path is about 20x slower; rates are per pair).
NUMPY_PAIRS = 100_000
GOLD_633 = 0.18 + 3.43j


def throughput() -> None:
    """eval and eval_mueller rates, both backends, both models."""
    wi, wo, _ = directions()
    models = {
        "RoughDielectric GGX 0.3, eta 1.51": lambda **kw: RoughDielectric("ggx", 0.3, 1.51,
                                                                          **kw),
        "RoughConductor GGX 0.3, gold": lambda **kw: RoughConductor("ggx", 0.3, GOLD_633, **kw),
    }
    load_before = os.getloadavg()[0]
    rows = []
    for name, make in models.items():
        for backend, n in ((None, N), ("numpy", NUMPY_PAIRS)):
            model = make(backend=backend)
            model.eval_mueller(wi[:10], wo[:10])  # compile (or load) outside the timing
            a, b = wi[:n], wo[:n]
            scale = N / n  # rate() counts N items
            ev = [r / scale for r in rate(lambda m=model, a=a, b=b: m.eval(a, b), 5)]
            mu = [r / scale for r in rate(lambda m=model, a=a, b=b: m.eval_mueller(a, b), 5)]
            rows.append((name, model.backend, ev, mu))
    print(f"{N:,} random pairs (numpy rows: {NUMPY_PAIRS:,}), float64; load average "
          f"{load_before:.1f} before, {os.getloadavg()[0]:.1f} after, on {os.cpu_count()} cores")
    print(f"{'':36s} {'backend':>7s} {'eval M/s':>9s} {'per CPU-s':>10s} {'mueller M/s':>12s}"
          f" {'per CPU-s':>10s} {'cost x eval':>11s}")
    for name, backend, ev, mu in rows:
        print(f"{name:36s} {backend:>7s} {ev[0] / 1e6:9.2f} {ev[2] / 1e6:10.2f} "
              f"{mu[0] / 1e6:12.2f} {mu[2] / 1e6:10.2f} {ev[2] / mu[2]:11.1f}")


def depolarised_share() -> None:
    """Orders >= 2's share of the incident power (energy_loss), which eval_mueller puts on M00
    alone: the most any other element of the integrated Mueller matrix can be off by."""
    print("\norders >= 2 added to M00 as an ideal depolariser: their share of the incident "
          "power (energy_loss; F = 1 for the conductors, an upper bound), which bounds the "
          "error of every other element integrated over wo, per unit incident power")
    thetas = (0.0, 30.0, 60.0, 75.0)
    print(f"{'':34s} " + " ".join(f"{t:>6.0f} deg" for t in thetas))
    cases = {"glass GGX 0.394 (ground)": ("ggx", 0.394, 1.51),
             "glass GGX 0.553 (acid-etched)": ("ggx", 0.553, 1.51),
             "glass Beckmann 0.023 (anti-glare)": ("beckmann", 0.023, 1.51),
             "conductor GGX 0.3, F = 1": ("ggx", 0.3, None),
             "conductor GGX 0.8, F = 1": ("ggx", 0.8, None)}
    for name, (dist, alpha, eta) in cases.items():
        shares = [energy_loss(dist, alpha, eta, np.radians(t)) for t in thetas]
        print(f"{name:34s} " + " ".join(f"{s:10.4f}" for s in shares))


if __name__ == "__main__":
    throughput()
    depolarised_share()
