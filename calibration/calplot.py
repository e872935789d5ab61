"""Plots of calibration runs (a plan's `calibrates = "detector" | "aperture" | "angles"`, kept
in the run's record): what each one measures, never a BSDF.

- detector: the dark offset of every range, and each range's dark-corrected reading at a stage
  position against the mean of the ranges that read it well (the range-to-range gains, and
  whether they hold from the faintest to the brightest power: the linearity);
- aperture: the dark-corrected power of the arm scan across the straight beam, linear, beside
  the beam readings' level (the plateau where the aperture takes in the whole beam);
- angles: each peak scan (repeats averaged, beam-normalised) against the arm's offset from
  where its peak sits when the stages have no zero offset: the fitted offsets shift it.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from calibration.calibrate import beam_normalised, peak_scans
from calibration.detector import correct_power, dark_offsets, position_key, range_key
from calibration.values import CalibrationError
from gonio.geometry import stage_angles

#: A position's reading on a range counts toward its mean when this many sigmas above dark.
MIN_SNR = 20.0


def _panels(fig: Any, n: int) -> np.ndarray:
    """n side-by-side axes with a light grid, the figure sized for them."""
    fig.set_size_inches(4.2 * n + 0.8, 3.8)
    axes = np.atleast_1d(fig.subplots(1, n))
    for ax in axes:
        ax.grid(True, which="both", lw=0.3, alpha=0.5)
    return axes


def _detector(readings: np.ndarray, fig: Any) -> None:
    axes = _panels(fig, 2)
    darks = dark_offsets(readings)
    ranges = sorted(float(k) for k in darks)
    left, right = axes
    dark = np.array([[darks[range_key(r)].value, darks[range_key(r)].sigma] for r in ranges])
    ppm = dark * 1e6 / np.array(ranges)[:, None]
    left.errorbar(ranges, ppm[:, 0], yerr=ppm[:, 1], fmt="o", color="k", ms=4)
    left.axhline(0.0, color="k", lw=0.6)
    left.set_xscale("log")
    left.set_xlabel("range full scale (W)")
    left.set_ylabel("dark offset (ppm of full scale)")
    left.set_title("dark offset per range", fontsize=9)
    rows = readings[(readings["kind"] == "sample") & ~readings["saturated"]]
    where = position_key(rows)
    cells = {}  # (position, range) -> net mean reading, if well above dark
    for p, r in {(int(p), float(r)) for p, r in zip(where, rows["range_w"], strict=True)}:
        power = rows["power_w"][(where == p) & (rows["range_w"] == r)]
        dark = darks.get(range_key(r))
        if dark is None or len(power) < 2:
            continue
        net = float(power.mean()) - dark.value
        if net > MIN_SNR * np.hypot(power.std(ddof=1) / np.sqrt(len(power)), dark.sigma):
            cells[p, r] = net
    shared = {p for p, _ in cells if sum(q == p for q, _ in cells) >= 2}
    if not shared:
        raise CalibrationError("no stage position was read with signal on two ranges or more")
    mean = {p: np.mean([v for (q, _), v in cells.items() if q == p]) for p in shared}
    for k, r in enumerate(sorted({r for p, r in cells if p in shared})):
        on = sorted((mean[p], v / mean[p]) for (p, q), v in cells.items() if q == r and p in shared)
        x, y = np.array(on).T
        right.plot(x, y, "o", ms=3, color=f"C{k % 10}", label=f"{range_key(r)} W range")
    right.axhline(1.0, color="k", lw=0.6)
    right.set_xscale("log")
    right.set_xlabel("mean net power of the position over its ranges (W)")
    right.set_ylabel("net reading / that mean")
    right.set_title("range-to-range gain and linearity (uncorrected)", fontsize=9)
    right.legend(fontsize=7)


def _aperture(readings: np.ndarray, fig: Any) -> None:
    ax = _panels(fig, 1)[0]
    sample = readings[readings["kind"] == "sample"]
    sample = sample[np.argsort(sample["arm_deg"], kind="stable")]
    net = correct_power(sample["power_w"], sample["range_w"], dark_offsets(readings), None)
    ax.plot(sample["arm_deg"], net, "o-", ms=3, lw=0.8, color="k", label="arm scan")
    beam = readings[(readings["kind"] == "beam") & ~readings["saturated"]]
    if len(beam):
        ax.axhline(float(np.median(beam["power_w"])), ls="--", color="C3", lw=1,
                   label=f"beam readings (median of {len(beam)})")
    ax.set_xlabel("arm (deg, as the stage reports it)")
    ax.set_ylabel("dark-corrected power (W)")
    ax.set_title("arm scan across the straight beam, sample retracted", fontsize=9)
    ax.legend(fontsize=7)


def _angles(readings: np.ndarray, fig: Any) -> None:
    scans = peak_scans(beam_normalised(readings, dark_offsets(readings), None)[0])
    axes = _panels(fig, len(scans))
    for ax, scan in zip(axes, scans, strict=True):
        s = float(np.mean(scan.sample_deg))
        transmitted = scan.side == "transmission"
        nominal = float(stage_angles(s, 0.0 if transmitted else s, transmission=transmitted)
                        .arm_deg)
        offset = (scan.arm_deg - nominal + 180.0) % 360.0 - 180.0
        ax.errorbar(offset, scan.power_w, yerr=scan.sigma_w, fmt="o", ms=3, color="k",
                    ecolor="0.5", elinewidth=0.8)
        ax.axvline(0.0, ls="--", color="C3", lw=1, label="peak with no zero offsets")
        peak = "transmitted" if transmitted else "specular"
        ax.set_title(f"{peak} peak, sample at {s:.3g} deg", fontsize=9)
        ax.set_xlabel("arm - that peak's arm (deg)")
    beam = np.any(readings["kind"] == "beam")
    axes[0].set_ylabel("net power / beam power" if beam else "net power (W)")
    axes[0].legend(fontsize=7)


#: How each kind of calibration run is drawn (gonio.plan.CALIBRATES names the kinds).
PLOTS: dict[str, Callable[[np.ndarray, Any], None]] = {
    "detector": _detector, "aperture": _aperture, "angles": _angles,
}


def plot_calibration(readings: np.ndarray, kind: str, out_png: str | Path, title: str) -> Path:
    """Write the figure of a calibration run of this kind (PLOTS) as a PNG; returns its path."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if kind not in PLOTS:
        raise CalibrationError(f"no plot for a run that calibrates {kind!r} "
                               f"(kinds: {', '.join(PLOTS)})")
    fig = plt.figure()
    try:
        PLOTS[kind](readings, fig)
        fig.suptitle(title, fontsize=10)
        fig.tight_layout()
        fig.savefig(out_png, dpi=110)
    finally:
        plt.close(fig)
    return Path(out_png)
