"""A quick-look plot of a run: raw detector power against the plan's outgoing angle, one curve
per (side, incidence), dark and beam levels as lines. Written into the run directory."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from gonio.store import open_run


def write_quicklook(run_dir: str | Path, out: str | Path | None = None) -> Path:
    """Plot raw power vs outgoing angle and save it as PNG (default RUN/plot.png)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    run = open_run(run_dir)
    r = run.readings()
    out = Path(out) if out is not None else run.path / "plot.png"
    fig, ax = plt.subplots(figsize=(7, 4.5))
    samples = r[r["kind"] == "sample"]
    for side in np.unique(samples["side"]):
        for ti in np.unique(samples["plan_theta_i_deg"][samples["side"] == side]):
            pick = samples[(samples["side"] == side) & (samples["plan_theta_i_deg"] == ti)]
            pick = pick[np.argsort(pick["plan_theta_o_deg"], kind="stable")]
            ax.plot(pick["plan_theta_o_deg"], np.maximum(pick["power_w"], 1e-15), ".-", ms=3,
                    label=f"{side}, theta_i = {ti:g} deg")
    for kind, style in (("dark", ":"), ("beam", "--")):
        pick = r[r["kind"] == kind]
        if len(pick):
            ax.axhline(max(float(np.nanmedian(pick["power_w"])), 1e-15), ls=style, color="k",
                       lw=0.8, label=f"{kind} (median of {len(pick)})")
    ax.set_yscale("log")
    ax.set_xlabel("outgoing angle from the normal of its side (deg; < 0: toward the source)")
    ax.set_ylabel("raw detector power (W)")
    ax.set_title(f"{run.meta.get('plan_name', run.path.name)}: {len(r)} readings, "
                 f"{run.status}")
    ax.grid(True, which="both", alpha=0.3)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out
