"""Detector calibration: dark offset per range, range-to-range gain ratios and a linearity check.

Model of a reading on range r: m = g_r * P + d_r + noise, gains relative to a reference range
(g_ref = 1). Dark offsets come from readings with no light; gains from the same optical powers
read on several ranges (a calibration plan run once per fixed range, or any runs whose points
repeat across ranges), fitted jointly with the powers and the darks.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares, minimize

from calibration.values import CalibrationError, Measured, weighted_mean


def range_key(range_w: float) -> str:
    """The text key of a range in calibration files ("1e-06")."""
    return f"{float(range_w):.6g}"


def dark_offsets(readings: np.ndarray) -> dict[str, Measured]:
    """Mean dark reading and its standard error on every range that has dark readings."""
    dark = readings[readings["kind"] == "dark"]
    if len(dark) == 0:
        raise CalibrationError("no dark readings (kind 'dark') to measure the dark offset from")
    out = {}
    for r in np.unique(dark["range_w"]):
        on_range = dark["power_w"][dark["range_w"] == r]
        if len(on_range) < 2:
            raise CalibrationError(f"range {range_key(r)} W: one dark reading cannot give an "
                                   "uncertainty; take at least two")
        out[range_key(r)] = weighted_mean(on_range)
    return out


@dataclass
class GainCalibration:
    """Gains per range relative to `reference`, and the linearity check of the joint fit."""

    reference: str
    gains: dict[str, Measured]
    chi2_dof: float  # of the multiplicative model over all positions and ranges
    max_deviation: float  # largest |reading / model - 1| of a well-measured reading
    exponents: dict[str, Measured]  # gamma of m_r ∝ m_ref^gamma, 1 for a linear detector


def gain_ratios(readings: np.ndarray, darks: dict[str, Measured],
                reference_w: float | None = None, min_snr: float = 20.0) -> GainCalibration:
    """Joint fit of range gains, per-position powers and the dark offsets (constrained by the
    dark readings, since a dark error is common to a whole range) from sample readings of the
    same stage positions on several ranges; saturated and low-signal cells are left out."""
    rows = readings[(readings["kind"] == "sample") & ~readings["saturated"]]
    rows = rows[shared_positions(rows)]
    ranges = sorted({float(r) for r in rows["range_w"]})
    if len(ranges) < 2:
        raise CalibrationError("gain ratios need the same positions read on at least two ranges; "
                               f"found range(s) {', '.join(map(range_key, ranges)) or 'none'}")
    reference = max(ranges) if reference_w is None else float(reference_w)
    if reference not in ranges:
        raise CalibrationError(f"reference range {range_key(reference)} W has no readings")
    missing = [range_key(r) for r in ranges if range_key(r) not in darks]
    if missing:
        raise CalibrationError(f"range {missing[0]} W has readings but no dark offset")
    # Average repeats of one (position, range); keep cells with a good signal. Positions are
    # numbered over all ranges at once: ranges may read different sets of positions.
    position = position_key(rows)
    cells = []
    for k, r in enumerate(ranges):
        on_range, where = rows[rows["range_w"] == r], position[rows["range_w"] == r]
        groups = [on_range["power_w"][where == p] for p in np.unique(where)]
        points = [int(p) for p, g in zip(np.unique(where), groups, strict=True) if len(g) >= 2]
        groups = [g for g in groups if len(g) >= 2]
        if not groups:
            continue
        sem = pooled_sem(groups)
        dark = darks[range_key(r)]
        for point, g, sigma in zip(points, groups, sem, strict=True):
            net = float(g.mean()) - dark.value
            if net > min_snr * math.hypot(sigma, dark.sigma):
                cells.append((point, k, float(g.mean()), float(sigma)))
    shared = sorted(p for p in {c[0] for c in cells}
                    if len({c[1] for c in cells if c[0] == p}) >= 2)
    cells = [c for c in cells if c[0] in shared]
    if not cells:
        raise CalibrationError("no position was read with enough signal on two ranges")
    return _solve_gains(cells, ranges, shared, ranges.index(reference), darks)


def pooled_sem(groups: list[np.ndarray], full_scale_w: np.ndarray | None = None) -> np.ndarray:
    """Standard error of each group's mean from a noise law pooled over the groups,
    variance = a FS^2 + c mean + b mean^2 (read noise and quantisation in proportion to the
    range's full scale FS, the signal's shot noise, relative noise; FS = 1 for groups of one
    range): a handful of repeats per group then still gives a trustworthy error. Without the
    shot term the law misses a photodiode's noise by factors 0.4-2.5 across a peak scan's
    ranges (shot noise dominates the lowest range's upper part), and the angle offsets' pulls
    widen to rms 1.3. The law is fitted by maximum likelihood (a sample variance of n readings
    is the law times chi2(n - 1) / (n - 1)), which stays stable where powers span decades
    (reweighted least squares on the variances flip-flopped between the terms)."""
    mean = np.array([g.mean() for g in groups])
    var = np.array([g.var(ddof=1) for g in groups])
    dof = np.array([len(g) for g in groups]) - 1.0
    scale = np.ones(len(groups)) if full_scale_w is None else np.asarray(full_scale_w, float)
    unit_v = max(float(var.max()), 1e-300)  # terms of order one
    design = np.stack([scale ** 2, np.maximum(mean, 0.0), mean ** 2], axis=1)
    design /= np.maximum(design.max(axis=0), 1e-300) / unit_v
    v = var / unit_v
    start = [max(float(np.median(v[column > 0] / column[column > 0])) if np.any(column > 0)
                 else 1.0, 1e-12) for column in design.T]

    def nll(log_coef: np.ndarray) -> float:
        model = design @ np.exp(log_coef) + 1e-300
        return float(np.sum(0.5 * dof * (np.log(model) + v / model)))

    bounds = [(math.log(x) - 40.0, math.log(x) + 10.0) for x in start]
    best = minimize(nll, np.log(start), method="L-BFGS-B", bounds=bounds)
    return np.sqrt((design @ np.exp(best.x) * unit_v) / (dof + 1.0))


def _solve_gains(cells: list[tuple[int, int, float, float]], ranges: list[float],
                 points: list[int], ref_index: int,
                 darks: dict[str, Measured]) -> GainCalibration:
    """Least squares for m_jr = g_r P_j + d_r: unknowns log g_r (r != ref), log P_j and d_r,
    with each d_r also tied to its dark-reading mean."""
    gain_cols = [k for k in range(len(ranges)) if k != ref_index]
    ng, npnt = len(gain_cols), len(points)
    point_of = np.array([points.index(c[0]) for c in cells])
    range_of = np.array([c[1] for c in cells])
    m, s = np.array([c[2] for c in cells]), np.array([c[3] for c in cells])
    dark = np.array([darks[range_key(r)].value for r in ranges])
    dark_s = np.array([max(darks[range_key(r)].sigma, 1e-300) for r in ranges])
    gain_index = np.array([gain_cols.index(k) if k != ref_index else -1 for k in range_of])

    def unpack(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        log_g = np.where(gain_index >= 0, x[np.maximum(gain_index, 0)], 0.0)
        return log_g, x[ng:ng + npnt][point_of], x[ng + npnt:]

    def residuals(x: np.ndarray) -> np.ndarray:
        log_g, log_p, d = unpack(x)
        model = np.exp(log_g + log_p) + d[range_of]
        return np.concatenate([(model - m) / s, (d - dark) / dark_s])

    log_p0 = [math.log(max(np.mean([c[2] - dark[c[1]] for c in cells if c[0] == p]), 1e-300))
              for p in points]
    x0 = np.concatenate([np.zeros(ng), log_p0, dark])
    sol = least_squares(residuals, x0, method="lm", xtol=1e-14, ftol=1e-14)
    jac = sol.jac
    if np.linalg.matrix_rank(jac) < len(x0):
        raise CalibrationError("the ranges are not linked: some range shares no position with "
                               "the others, so its gain cannot be related to the reference")
    cov = np.linalg.inv(jac.T @ jac)
    dof = max(len(cells) - ng - npnt, 1)
    chi2_dof = float(np.sum(sol.fun[:len(cells)] ** 2) / dof)
    cov *= max(1.0, chi2_dof)
    gains = {range_key(ranges[ref_index]): Measured(1.0, 0.0)}
    for k, rk in enumerate(gain_cols):
        g = math.exp(sol.x[k])
        gains[range_key(ranges[rk])] = Measured(g, g * math.sqrt(cov[k, k]))
    log_g, log_p, d = unpack(sol.x)
    net = m - d[range_of]
    deviation = np.abs(net / np.exp(log_g + log_p) - 1.0)
    net_cells = [(c[0], c[1], float(n), c[3]) for c, n in zip(cells, net, strict=True)]
    return GainCalibration(
        reference=range_key(ranges[ref_index]), gains=gains, chi2_dof=chi2_dof,
        max_deviation=float(deviation.max()),
        exponents=_linearity_exponents(net_cells, ranges, ref_index),
    )


def _linearity_exponents(cells: list[tuple[int, int, float, float]], ranges: list[float],
                         ref_index: int) -> dict[str, Measured]:
    """Slope gamma of log m_r against log m_ref over shared positions (needs three or more)."""
    ref = {c[0]: (c[2], c[3]) for c in cells if c[1] == ref_index}
    out = {}
    for rk, r in enumerate(ranges):
        pairs = [(ref[c[0]], (c[2], c[3])) for c in cells if c[1] == rk and c[0] in ref]
        if rk == ref_index or len(pairs) < 3:
            continue
        x = np.log([p[0][0] for p in pairs])
        y = np.log([p[1][0] for p in pairs])
        sy = np.hypot([p[0][1] / p[0][0] for p in pairs], [p[1][1] / p[1][0] for p in pairs])
        if np.ptp(x) <= 0:
            continue
        coef, cov = np.polyfit(x, y, 1, w=1.0 / sy, cov="unscaled")
        out[range_key(r)] = Measured(float(coef[0]), float(math.sqrt(cov[0, 0])))
    return out


def position_key(rows: np.ndarray) -> np.ndarray:
    """An integer per distinct stage position (to 0.001 deg): readings at one position see the
    same optical power, whichever run or plan took them."""
    stages = np.stack([rows[n] for n in ("sample_deg", "arm_deg", "azimuth_deg",
                                         "elevation_deg")], axis=1)
    return np.unique(np.round(stages, 3), axis=0, return_inverse=True)[1].ravel()


def shared_positions(rows: np.ndarray) -> np.ndarray:
    """Mask of the readings at stage positions read (twice or more) on two ranges or more."""
    where = position_key(rows)
    keep = np.zeros(len(rows), bool)
    for point in np.unique(where):
        at = where == point
        ranges, counts = np.unique(rows["range_w"][at], return_counts=True)
        if np.sum(counts >= 2) >= 2:
            keep |= at
    return keep


def ranges_read_together(readings: np.ndarray) -> bool:
    """True if some stage position was read (twice or more) on each of two ranges or more: what
    gain_ratios needs. An autoranged run reads each position on one range only."""
    rows = readings[(readings["kind"] == "sample") & ~readings["saturated"]]
    return bool(shared_positions(rows).any())


def dark_for(darks: dict[str, Measured], range_w: float) -> Measured:
    """The dark offset of a range: its own, else that of the nearest range measured (dark
    readings autorange to the most sensitive range; a photodiode's dark current is the same
    power on every range, and on coarser ranges the offset is far below the signal)."""
    key = range_key(range_w)
    if key in darks:
        return darks[key]
    if not darks:
        raise CalibrationError("the calibration has no dark offsets")
    nearest = min(darks, key=lambda k: abs(np.log10(float(k)) - np.log10(float(range_w))))
    return darks[nearest]


def correction_sigma_w(power_w: np.ndarray, range_w: np.ndarray, darks: dict[str, Measured],
                       gains: dict[str, Measured] | None) -> np.ndarray:
    """Per corrected power (correct_power's output), its sigma from the calibration's own
    errors, the dark offset and gain of its range: common to every reading on that range, so
    the scatter of repeats does not show them."""
    out = np.empty(len(power_w))
    for r in np.unique(range_w):
        sel = range_w == r
        gain = Measured(1.0, 0.0) if gains is None else gains[range_key(r)]
        out[sel] = np.hypot(dark_for(darks, r).sigma / gain.value,
                            power_w[sel] * gain.sigma / gain.value)
    return out


def correct_power(power_w: np.ndarray, range_w: np.ndarray, darks: dict[str, Measured],
                  gains: dict[str, Measured] | None) -> np.ndarray:
    """Readings -> power on the reference range's scale: (m - d_r) / g_r per reading."""
    out = np.empty(len(power_w))
    for r in np.unique(range_w):
        key = range_key(r)
        gain = 1.0
        if gains is not None:
            if key not in gains:
                raise CalibrationError(f"the calibration has no gain for range {key} W")
            gain = gains[key].value
        sel = range_w == r
        out[sel] = (power_w[sel] - dark_for(darks, r).value) / gain
    return out
