"""What the fit's orders >= 3 would cost at issue 19's accuracy: walks per direction, both ways.

Walter's ground glass and acid-etched glass are scanned afresh at normal incidence (as in
bench/ms_model_error.py). At each fit point this prints the orders >= 3 as a share of f and in
units of the data's noise (ms_model_error's NOISE_COMPONENTS: the run's own noise, without the
budget's stated type-B terms, the scale of issue 19's goal), and the per-walk coefficient of
variation of two unbiased estimators of them: forward, the keyed shared-path walk from wi that
scores every distinct polar angle at once (what the fit walks), and reverse, the same walk
started from the target towards wi alone
(reciprocity: f(wi, wo) / n_o^2 = f(wo, wi) / n_i^2). From those it works out the walks and CPU
seconds per fit-table alpha that would put the standard error at 0.45 of the noise at the
median point (a median |error| of 0.3) and at 0.67 of it at every point (the worst of 133 points
x 4 seeds then near 2): forward, the walks the hardest point needs (all points share
them); reverse, each distinct polar angle its own walks. Every walk is drawn from --seeds seeds
(SEEDS): each figure is the median over them, the coefficients of variation and the walks and
seconds the goals need with their [min, max] (the worst point's need rests on the few walks
that reach it, so one draw of it says little).
Run: python bench/ms_orders3_cost.py [--seeds 8] [--forward-walks 262144] [--reverse-walks 32768]"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _seeds import SEEDS, median_range  # noqa: E402
from ms_model_error import distinct_polar, fit_points, glass  # noqa: E402

from calibration.fit import MS_CENTRE_WALKS, FitOptions  # noqa: E402
from model.bsdf.multiple_scattering.keyed import keyed_walk_to_targets  # noqa: E402

NORMAL = np.array([0.0, 0.0, 1.0])
#: Standard error / data noise for a median |error| of 0.3, and for the worst of ~530 errors
#: (133 points x 4 seeds) near 2.
MEDIAN_GOAL, WORST_GOAL = 0.3 / 0.674, 2.0 / 3.0
#: Walks of the fit table's centre alpha (calibration.fit: ms_walks x MS_CENTRE_WALKS).
CENTRE = FitOptions().ms_walks * MS_CENTRE_WALKS
SHOWN_DEG = (7.5, 30.0, 60.0, 82.5, 97.5, 112.5, 127.5, 142.5, 165.0)


def per_walk(walker, wi: np.ndarray, targets: np.ndarray, walks: int, seed: int | tuple[int, int]
             ) -> tuple[np.ndarray, np.ndarray, float]:
    """(orders >= 3 of f |cos o| per target, per-walk coefficient of variation, CPU s per
    walk) of `walks` keyed walks from wi."""
    start = time.process_time()
    mean, err, _ = keyed_walk_to_targets(walker, wi, targets, walks,
                                         np.random.default_rng(seed), 3, False)
    seconds = (time.process_time() - start) / walks
    return mean, err / np.where(mean > 0, mean, np.inf) * np.sqrt(walks), seconds


def one_seed(walker, targets: np.ndarray, args: argparse.Namespace, seed: int
             ) -> tuple[np.ndarray, ...]:
    """(orders >= 3 of f |cos o|, CV forward, CV reverse, reverse CPU s per walk) per distinct
    polar angle, and the forward CPU s per walk, from one seed's walks."""
    mean, cv_fwd, s_fwd = per_walk(walker, NORMAL, targets, args.forward_walks, seed)
    cv_rev, s_rev = np.zeros(len(targets)), np.zeros(len(targets))
    for t in range(len(targets)):
        _, cv, s_rev[t] = per_walk(walker, targets[t], NORMAL[None, :], args.reverse_walks,
                                   (seed, t))
        cv_rev[t] = cv[0]
    return mean, cv_fwd, cv_rev, s_rev, np.float64(s_fwd)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=SEEDS)
    ap.add_argument("--forward-walks", type=int, default=1 << 18)
    ap.add_argument("--reverse-walks", type=int, default=1 << 15)
    args = ap.parse_args()
    print(f"load average {os.getloadavg()[0]:.1f}; forward {args.forward_walks} walks, reverse "
          f"{args.reverse_walks} walks per point, each from {args.seeds} seeds: the median over "
          f"them [min, max]; CV: per-walk coefficient of variation")
    with tempfile.TemporaryDirectory() as tmp:
        for name, alpha, wo, _, noise, f in fit_points(Path(tmp)):
            walker = glass(alpha).walker
            targets, index = distinct_polar(wo)
            per_walk(walker, NORMAL, targets[:2], 64, 0)  # compile outside the timings
            runs = [one_seed(walker, targets, args, seed) for seed in range(1, args.seeds + 1)]
            mean, cv_fwd, cv_rev, s_rev = (np.array([run[k] for run in runs])[:, index]
                                           for k in range(4))
            s_fwd = np.array([run[4] for run in runs])
            polar = np.degrees(np.arccos(wo[:, 2]))
            distinct = np.unique(index, return_index=True)[1]
            share = mean / np.abs(wo[:, 2]) / noise  # orders >= 3 in data noise, per seed
            print(f"\n{name} (GGX {alpha}, {len(wo)} points): forward "
                  f"{np.median(s_fwd) * 1e6:.2f} us per walk (every polar angle), reverse "
                  f"{np.median(s_rev) * 1e6:.2f} us (one)")
            print(f"{'theta_o':>8} {'o3 / f':>8} {'o3 / noise':>10} {'CV fwd':>18} "
                  f"{'CV rev':>18}")
            for deg in SHOWN_DEG:
                t = int(np.argmin(np.abs(polar - deg)))
                print(f"{polar[t]:8.1f} {np.median(mean[:, t]) / abs(wo[t, 2]) / f[t]:8.4f} "
                      f"{np.median(share[:, t]):10.1f} {median_range(cv_fwd[:, t], '.1f'):>18} "
                      f"{median_range(cv_rev[:, t], '.1f'):>18}")
            need_fwd = (share * cv_fwd) ** 2
            median = np.median(need_fwd, axis=1) / MEDIAN_GOAL ** 2
            worst = need_fwd.max(axis=1) / WORST_GOAL ** 2
            reverse = np.sum(((share * cv_rev / WORST_GOAL) ** 2 * s_rev)[:, distinct], axis=1)
            print(f"  per table alpha: the fit's centre now {CENTRE} forward walks = "
                  f"{CENTRE * np.median(s_fwd):.2f} CPU s; {MEDIAN_GOAL:.2f} noise at the median "
                  f"point: {median_range(median, '.3g')} forward walks = "
                  f"{median_range(median * s_fwd, '.1f')} s")
            print(f"  {WORST_GOAL:.2f} noise at every point: {median_range(worst, '.3g')} forward "
                  f"walks = {median_range(worst * s_fwd, '.0f')} s, or reverse walks per point "
                  f"{median_range(reverse, '.0f')} s")


if __name__ == "__main__":
    main()
