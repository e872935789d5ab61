"""Fit time and parameter error against the number of measured points (normal incidence).

For Walter's anti-glare (Beckmann 0.023) and ground glass (GGX 0.394) samples, synthetic
reduced data (2 % relative noise, six-decade floor) with N points are fitted by
calibration.fit (one distribution, the generating one, so times compare like with like).
Baseline in the same run: a Nelder-Mead minimisation of the same chi-square from the same start
(scipy.optimize.minimize), the approach a quick script would take.

Times are the fastest of three runs of each fit (the machine is shared), the median over seeds;
|err| (alpha's relative error) the median [min, max] over seeds, the others the median; pull
rms over all seeds.
Run: python bench/fit_time.py [--seeds 8]
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np
from _seeds import SEEDS, median_range
from scipy.optimize import minimize

from calibration.fit import FitOptions, build_model, fit, initial_alpha
from calibration.synthetic import synthesize

SAMPLES = (("beckmann", 0.023), ("ggx", 0.394))
SIZES = ((12, 4), (24, 8), (48, 16), (96, 32), (192, 64), (384, 128))  # per side


def nelder_mead(data, distribution: str, alpha0: float) -> tuple[float, int]:
    """Baseline: Nelder-Mead on the chi-square in log alpha; returns (alpha, evaluations)."""
    def chi2(x: np.ndarray) -> float:
        f = build_model(distribution, math.exp(x[0]), 1.51, "separable").eval(data.wi, data.wo)
        return float(np.sum(((f - data.bsdf) / data.sigma) ** 2))

    res = minimize(chi2, [math.log(alpha0)], method="Nelder-Mead",
                   options={"xatol": 1e-6, "fatol": 1e-6})
    return math.exp(res.x[0]), res.nfev


def best_of(job, *args, repeats: int = 3):
    """(job(*args), fastest wall time of `repeats` runs): the machine is shared, so the minimum
    is the figure least disturbed by other load."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = job(*args)
        times.append(time.perf_counter() - t0)
    return out, min(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=SEEDS)
    args = parser.parse_args()
    print(f"{args.seeds} seeds per row")
    print(f"{'sample':<16}{'N':>6}{'fit ms':>9}{'|err| % [min, max]':>25}{'sigma %':>9}"
          f"{'pull rms':>9}{'NM ms':>9}{'NM |err| %':>11}{'NM nfev':>8}")
    for distribution, alpha in SAMPLES:
        for n_uniform, n_peak in SIZES:
            t_fit, t_nm, err, err_nm, sig, pulls, nfev = [], [], [], [], [], [], []
            for seed in range(args.seeds):
                data = synthesize(distribution, alpha, seed=seed, incidences_deg=(0.0,),
                                  n_uniform=n_uniform, n_peak=n_peak)
                result, seconds = best_of(fit, data, FitOptions(distributions=(distribution,)))
                t_fit.append(seconds)
                value, sigma = result.param("alpha")
                err.append(abs(value / alpha - 1))
                sig.append(sigma / alpha)
                pulls.append((value - alpha) / sigma)
                (a_nm, n_eval), seconds = best_of(nelder_mead, data, distribution,
                                                  initial_alpha(data, 1.51))
                t_nm.append(seconds)
                err_nm.append(abs(a_nm / alpha - 1))
                nfev.append(n_eval)
            print(f"{distribution + ' ' + str(alpha):<16}{len(data.bsdf):>6}"
                  f"{1e3 * np.median(t_fit):>9.1f}{median_range(100 * np.array(err), '.3f'):>25}"
                  f"{100 * np.median(sig):>9.3f}{math.sqrt(np.mean(np.square(pulls))):>9.2f}"
                  f"{1e3 * np.median(t_nm):>9.1f}{100 * np.median(err_nm):>11.3f}"
                  f"{int(np.median(nfev)):>8}")


if __name__ == "__main__":
    main()
