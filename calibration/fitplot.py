"""The fit overlay of `gonio plot RUN --fit`: per incidence angle, the measured BSDF with its
error bars against the signed outgoing angle (log scale), the fitted model through it, and the
normalised residuals (data - model) / sigma below (sigma: the data's and the model's own Monte
Carlo error, as the fit weighs them), fitted and held-out points told apart."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from calibration.fit import FitOptions, FitResult, fit_subset_mask
from calibration.reduced import ReducedData
from model.optics.directions import in_plane_directions


def model_curve(result: FitResult, theta_i_deg: float, transmission: bool,
                n: int = 721) -> tuple[np.ndarray, np.ndarray]:
    """(signed outgoing angle deg, model BSDF) along the plane of incidence on one side, in the
    ReducedData.theta_o_deg convention (positive on the forward side)."""
    theta_deg = np.linspace(-89.5, 89.5, n)
    wi, wo = in_plane_directions(theta_i_deg, theta_deg, transmission)
    return theta_deg, result.predict(wi, wo)


def fit_warning(result: FitResult) -> str:
    """The warning a fit that does not describe its data carries (chi2/dof, fitted or held out,
    above calibration.exports.model.MAX_CHI2_DOF, which model exports refuse), else ""."""
    from calibration.fit.result import MAX_CHI2_DOF, worst_chi2_dof

    worst, which = worst_chi2_dof(result.chi2_dof_fit, result.chi2_dof_heldout)
    if worst <= MAX_CHI2_DOF:
        return ""
    return (f"WARNING: {which} χ²/dof {worst:.3g} > {MAX_CHI2_DOF:g}: the model does not "
            "describe the data within their uncertainties")


def fitted_model_name(result: FitResult) -> str:
    """The fitted model as the overlay's legend names it: a family, or the distribution."""
    return result.distribution if result.family == "microfacet" else result.family


def fit_title(data: ReducedData, result: FitResult, title: str = "") -> str:
    """The overlay's title: the run's (title: its name, sample and nominal eta), then the fitted
    parameters, eta only where it tells something new (fitted, or held at another value),
    then chi2/dof on the fitted and held-out points, and fit_warning's line for a bad fit."""
    held = "–" if result.chi2_dof_heldout is None else f"{result.chi2_dof_heldout:.4g}"
    lines = [title] if title else []
    chi2 = f"χ²/dof fitted {result.chi2_dof_fit:.4g}, held out {held}"
    warning = fit_warning(result)
    if result.family != "microfacet":  # a model family's parameters by name, held ones too
        from calibration.exports.family_fit import family_fit

        lines += [f"{family_fit(result).describe()} fit", chi2]
        return "\n".join([*lines, warning] if warning else lines)
    a = np.atleast_1d(result.alpha)
    eta = ""
    if "eta" in result.names:
        value, sigma = result.param("eta")
        eta = f", η = {value:.4g} ± {sigma:.2g} (fitted)"
    elif data.meta.get("eta") is None or abs(result.eta - data.meta["eta"]) > 1e-12:
        eta = f", η = {result.eta:.4g} (held)"
    lines += [f"{result.distribution} fit α = {', '.join(f'{v:.4g}' for v in a)}{eta}", chi2]
    return "\n".join([*lines, warning] if warning else lines)


def plot_fit(data: ReducedData, result: FitResult, out_png: str | Path,
             options: FitOptions | None = None, title: str = "") -> Path:
    """Write the overlay figure (a column per incidence, BSDF and residual rows per measured side)
    as a PNG; returns its path."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    options = options or FitOptions()
    fitted = fit_subset_mask(data, options)
    valid = data.valid & np.isfinite(data.bsdf) & (data.sigma > 0)
    theta_i = np.round(data.theta_i_deg, 1)
    incidences = list(np.unique(theta_i[valid]))
    sides = [side for side in (False, True) if np.any(valid & (data.transmission == side))]
    fig, axes = plt.subplots(2 * len(sides), len(incidences), squeeze=False, sharex="col",
                             figsize=(3.4 * len(incidences), 3.6 * len(sides)),
                             gridspec_kw={"height_ratios": [3, 1] * len(sides)})
    # against the data's sigma and the model's own Monte Carlo error (multiple scattering),
    # as the fit weighs them
    model, model_sigma = result.predict_with_error(data.wi, data.wo)
    residual = (model - data.bsdf) / np.hypot(data.sigma, model_sigma)
    for row, side in enumerate(sides):
        for col, t in enumerate(incidences):
            top, bottom = axes[2 * row, col], axes[2 * row + 1, col]
            sel = valid & (theta_i == t) & (data.transmission == side)
            for mask, style, label in ((sel & fitted, "o", "fitted"),
                                       (sel & ~fitted, "s", "held out")):
                if mask.any():
                    top.errorbar(data.theta_o_deg[mask], data.bsdf[mask], data.sigma[mask],
                                 fmt=style, ms=3, lw=0.8, label=label)
                    bottom.plot(data.theta_o_deg[mask], -residual[mask], style, ms=3)
            angle, curve = model_curve(result, float(t), bool(side))
            top.plot(angle, curve, "k-", lw=1, label=f"{fitted_model_name(result)} fit")
            top.set_yscale("log")
            positive = data.bsdf[sel][data.bsdf[sel] > 0]
            if positive.size:
                top.set_ylim(max(positive.min() / 3, curve.max() * 1e-8), curve.max() * 3)
            top.set_title(f"θi = {t:g}°, {'BTDF' if side else 'BRDF'}", fontsize=9)
            bottom.axhline(0.0, color="k", lw=0.6)
            bottom.set_xlabel("θo (deg)")
            if col == 0:
                top.set_ylabel("BSDF (1/sr)")
                bottom.set_ylabel("(data − model)/σ", fontsize=8)  # σ: data ⊕ model
            if sel.any():
                top.legend(fontsize=7)
    fig.suptitle(fit_title(data, result, title), fontsize=9,
                 color="C3" if fit_warning(result) else "k")
    fig.tight_layout()
    out_png = Path(out_png)
    fig.savefig(out_png, dpi=110)
    plt.close(fig)
    return out_png
