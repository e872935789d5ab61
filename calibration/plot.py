"""Paper-style plots of a run (`gonio plot RUN`): per incidence angle, the measured BSDF with its
error bars against the signed outgoing angle on a log scale, reflection and transmission, as in
Walter et al. 2007's figures; for a run whose devices were all emulated, with the emulator's
truth ("emulator truth": the bench's own BSDF, point values and aperture-averaged). A real run
has no truth curve. `--fit` hands over to calibration.fitplot's overlay."""

from __future__ import annotations

import textwrap
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from calibration.emulator_truth import EmulatorTruth, truth_of
from calibration.reduced import ReducedData
from calibration.values import CalibrationError

#: Characters per line of a legend label (a panel is 3.4 inches wide at 7 pt).
LEGEND_WIDTH = 44

if TYPE_CHECKING:
    from gonio.store import Run


def signed_theta_o_deg(data: ReducedData) -> np.ndarray:
    """In-plane outgoing angle from the normal on its side, positive on the forward side
    (away from the source; +x at normal incidence, so both halves stay apart there)."""
    cos_o = np.where(data.transmission, -data.wo[:, 2], data.wo[:, 2])
    theta = np.degrees(np.arccos(np.clip(cos_o, -1.0, 1.0)))
    forward = np.where(data.wi[:, 0] != 0.0, -np.sign(data.wi[:, 0]), 1.0)
    return np.where(data.wo[:, 0] * forward < 0, -theta, theta)


def truth_curves(meta: dict, truth: EmulatorTruth | None, theta_i_deg: float,
                 transmission: bool) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """{label: (signed theta_o deg, BSDF)} of the emulator's truth (`truth`:
    emulated_truth(meta)): point values, and averaged over the aperture when the reduction's
    meta gives its half-angle. Empty for a run that was not all emulated (truth None)."""
    if truth is None:
        return {}
    return truth.curves(theta_i_deg, transmission,
                        float(meta.get("aperture_half_angle_deg") or 0.0))


def emulated_truth(meta: dict) -> EmulatorTruth | None:
    """The emulator's truth of the run whose reduction's meta this is (its [sim] table on its
    [optics] and [sample]), or None for any run with a real device."""
    return truth_of(meta.get("sim"), meta.get("optics"), meta.get("sample"))


def x_range(theta_deg: np.ndarray) -> tuple[float, float]:
    """Outgoing-angle axis: the whole plane, or zoomed onto a narrow lobe's measured points."""
    if theta_deg.size < 2 or np.ptp(theta_deg) > 40.0:
        return -90.0, 90.0
    margin = max(2.0, 0.3 * float(np.ptp(theta_deg)))
    return max(-90.0, theta_deg.min() - margin), min(90.0, theta_deg.max() + margin)


def in_plane(data: ReducedData) -> np.ndarray:
    """The points in the plane of incidence (phi_o = 0 or 180 deg): what the figures show."""
    return np.abs(data.wo[:, 1]) < 1e-6


def panel_limits(theta_o_deg: np.ndarray, bsdf: np.ndarray, good: np.ndarray
                 ) -> tuple[tuple[float, float], tuple[float, float] | None]:
    """(x range, y range) of one figure panel from its points (`good`: valid, positive): the
    outgoing angles zoomed onto the lobe (x_range), the values with some room; y None when
    no point is good."""
    lobe = good & (bsdf > 1e-5 * bsdf[good].max()) if good.any() else good
    positive = bsdf[good]
    y = ((max(positive.min() / 5, positive.max() * 1e-7), positive.max() * 5)
         if positive.size else None)
    return x_range(theta_o_deg[lobe]), y


def plot_reduced(data: ReducedData, out_png: str | Path, title: str = "") -> Path:
    """Write the figure: a column per incidence angle, a row per measured side; PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    shown = in_plane(data)
    if not shown.any():
        raise CalibrationError("no in-plane points to plot (phi_o = 0)")
    data = data.subset(shown)
    theta_i = np.round(data.theta_i_deg, 1)
    incidences = sorted(set(theta_i.tolist()))
    sides = [s for s in (False, True) if (data.transmission == s).any()]
    theta_o = signed_theta_o_deg(data)
    truth = emulated_truth(data.meta)
    fig, axes = plt.subplots(len(sides), len(incidences), squeeze=False,
                             figsize=(3.4 * len(incidences) + 0.8, 3.0 * len(sides) + 0.8))
    for col, ti in enumerate(incidences):
        for row, transmission in enumerate(sides):
            ax = axes[row, col]
            sel = (theta_i == ti) & (data.transmission == transmission)
            good = sel & data.valid & (data.bsdf > 0)
            ax.errorbar(theta_o[good], data.bsdf[good], yerr=data.sigma[good], fmt="o", ms=3,
                        color="k", ecolor="0.5", elinewidth=0.8, label="measured")
            bad = sel & ~data.valid & (data.bsdf > 0)
            if bad.any():
                ax.plot(theta_o[bad], data.bsdf[bad], "o", ms=3, mfc="none", color="0.6",
                        label="flagged (dark-limited / saturated)")
            curves = truth_curves(data.meta, truth, ti, transmission)
            for (label, (x, y)), style in zip(curves.items(), ("-", "--"), strict=False):
                ax.plot(x, np.where(y > 0, y, np.nan), style, color="C3", lw=1.2, label=label)
            ax.set_yscale("log")
            x_lim, y_lim = panel_limits(theta_o, data.bsdf, good)
            ax.set_xlim(*x_lim)
            ax.grid(True, which="both", lw=0.3, alpha=0.5)
            side = "transmission" if transmission else "reflection"
            ax.set_title(f"theta_i = {ti:g} deg, {side}", fontsize=9)
            if row == len(sides) - 1:
                ax.set_xlabel("outgoing angle (deg, forward > 0)")
            if col == 0:
                ax.set_ylabel("BSDF (1/sr)")
            if y_lim is not None:
                ax.set_ylim(*y_lim)
    handles, labels = axes[0, 0].get_legend_handles_labels()  # wrapped to the panel's width:
    # a family's truth names all its parameters, and tight_layout would widen the gaps for it
    axes[0, 0].legend(handles, [textwrap.fill(label, LEGEND_WIDTH) for label in labels],
                      fontsize=7, loc="lower left")
    fig.suptitle(title or "measured BSDF", fontsize=10)
    fig.tight_layout()
    out_png = Path(out_png)
    fig.savefig(out_png, dpi=110)
    plt.close(fig)
    return out_png


#: The plot title's line of a reduction whose U leaves the angle terms out.
ANGLE_TERMS_LEFT_OUT = ("U excludes the angle terms (--no-angle-terms): the stages' "
                        "repeatability and angle offsets")


def plot_title(name: str, meta: dict) -> str:
    """The run's name and what was measured: the [sample] id and nominal eta (none for a panel
    without one); a line for an
    incomplete run (meta["completeness"], completeness_line) and one when U excludes the
    angle terms (meta["budget"]["angle_terms"], calibration.pipeline)."""
    sample = meta.get("sample") or {}
    excluded = (meta.get("budget") or {}).get("angle_terms") == "excluded"
    eta = meta.get("eta", float("nan"))
    return (f"{name}: sample {sample.get('id', '?')}"
            + (f", eta {eta:g}" if eta is not None else "")
            + completeness_line(meta.get("completeness"))
            + ("\n" + ANGLE_TERMS_LEFT_OUT if excluded else ""))


def completeness_line(completeness: dict | None) -> str:
    """"\n" and gonio.completeness's line for an incomplete run, else ""."""
    if not completeness or completeness["complete"]:
        return ""
    from gonio.completeness import Completeness

    return "\n" + Completeness.from_json(completeness).text()


def plot_run(run_dir: str | Path | Run, out_png: str | Path | None = None, fit: bool = False,
             calibration_file: str | Path | None = None, fit_options=None,
             shot_noise_w: float | None = None, subtract_signature: bool = False,
             angle_terms: bool = True, fitted: Callable[[Any], None] | None = None) -> Path:
    """Reduce a run (its directory, or the Run already open) and write its plot (default
    RUN/plot.png); with fit=True fit the model
    (calibration.fit), tell `fitted` the result (a FitResult) and draw the fitting area's
    overlay with residuals (RUN/plot-fit.png); subtract_signature, angle_terms as
    calibration.pipeline.reduce_run. A calibration run (its record's `calibrates`) gets the plot
    of what it measures instead (calibration.calplot)."""
    from calibration.pipeline import reduce_run
    from gonio.completeness import completeness_of
    from gonio.record import run_record
    from gonio.store import Run, open_run

    run = run_dir if isinstance(run_dir, Run) else open_run(run_dir)
    run_dir = run.path
    kind = run_record(run)["calibrates"]
    if kind is not None:
        from calibration.calplot import plot_calibration

        if fit:
            raise CalibrationError(f"{run_dir} calibrates the {kind}: no BSDF to fit (gonio "
                                   f"calibrate build {run_dir} --out CAL.json uses it)")
        title = (f"{run_dir.name}: {kind} calibration"
                 + completeness_line(completeness_of(run).to_json()))
        return plot_calibration(run.readings(), kind, out_png or run_dir / "plot.png", title)
    data = reduce_run(run, calibration_file, shot_noise_w, subtract_signature,
                      angle_terms=angle_terms)
    title = plot_title(run_dir.name, data.meta)
    if fit:
        from calibration.fit import select
        from calibration.fitplot import plot_fit

        result = select(data, fit_options)
        if fitted is not None:
            fitted(result)
        return plot_fit(data, result, out_png or run_dir / "plot-fit.png", fit_options,
                        title=title)
    return plot_reduced(data, out_png or run_dir / "plot.png", title=title)
