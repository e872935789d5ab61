"""Evaluations and samples per second of the model families, beside the microfacet model.

Throughput of each family of model.bsdf.families (Lambert, Oren-Nayar full and qualitative,
the coated diffuse surface over GGX and Beckmann coats, ABg, Rayleigh-Rice) on 1,000,000 random
direction pairs above the surface, eval() and sample() (each sample's weight f cos / pdf
included), beside RoughDielectric GGX (alpha 0.3, eta 1.51, its default backend) on the same
pairs in the same run; then the coated model's albedo table, its build time against its
white-furnace error (the table's interpolant against 1024^2-strata sums at the exact
incidence), the directional albedo of Oren-Nayar (rho = 1) and ABg (by stratified sums of
sample() weights, ABg beside its closed-form total integrated scatter), and Rayleigh-Rice's
scatter integral over the smooth-surface TIS R (4 pi sigma_rel cos_i / lambda)^2 as the
correlation length grows against the wavelength. Median of several runs, compile time excluded;
the CPU-time rate is printed beside the wall-clock one (the machine is shared).

    python bench/bsdf_families.py [--picture docs/img/bsdf_families.png]

--picture also draws each family's in-plane f cos_o at two incidences."""

from __future__ import annotations

import argparse
import math
import os
import time

import numpy as np
from bsdf_throughput import N, directions, rate

from model.bsdf import ABg, CoatedDiffuse, Lambert, OrenNayar, RayleighRice, RoughDielectric
from model.bsdf.families.coated import TABLE_MU, AlbedoTable

WHITE_THETAS = np.array([0.0, 0.5, 1.0, 1.3, 1.45, 1.52, 1.56])
ALBEDO_THETAS = (0.0, 0.5, 1.0, 1.3, 1.5)


def upper_pairs() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """bsdf_throughput's pairs and uniforms, both directions turned above the surface."""
    wi, wo, u = directions()
    wi[:, 2], wo[:, 2] = np.abs(wi[:, 2]), np.abs(wo[:, 2])
    return wi, wo, u


def stratified(n: int) -> np.ndarray:
    """n^2 stratified uniforms (cell midpoints in u1, u2; u3 = 0.5)."""
    e = (np.arange(n) + 0.5) / n
    u1, u2 = np.meshgrid(e, e, indexing="ij")
    return np.stack([u1.ravel(), u2.ravel(), np.full(u1.size, 0.5)], axis=-1)


def incidence(theta: float) -> np.ndarray:
    return np.array([math.sin(theta), 0.0, math.cos(theta)])


def throughput() -> None:
    wi, wo, u = upper_pairs()
    models = {
        "RoughDielectric GGX (microfacet)": RoughDielectric("ggx", 0.3, 1.51),
        "Lambert": Lambert(0.8),
        "Oren-Nayar full": OrenNayar(0.8, 0.3),
        "Oren-Nayar qualitative": OrenNayar(0.8, 0.3, "qualitative"),
        "coated, GGX coat": CoatedDiffuse(0.6, 0.2, 1.5),
        "coated, Beckmann coat": CoatedDiffuse(0.6, 0.2, 1.5, "beckmann"),
        "ABg (2e-3, 1e-3, 2)": ABg(2e-3, 1e-3, 2.0),
        "ABg (0.05, 0.02, 1.5)": ABg(0.05, 0.02, 1.5),
        "Rayleigh-Rice glass, 1 nm, 2 um, 2": RayleighRice(1.0, 2.0, 2.0, eta=1.5),
        "Rayleigh-Rice Al, 2 nm, 20 um, 3": RayleighRice(2.0, 20.0, 3.0, eta=1.37, k=7.6),
    }
    load_before = os.getloadavg()[0]
    rows = []
    for name, model in models.items():
        model.eval(wi[:10], wo[:10])  # compile (or load) outside the timing
        model.sample(wi[:10], u[:10])
        rows.append((name, rate(lambda m=model: m.eval(wi, wo), 5),
                     rate(lambda m=model: m.sample(wi, u), 3)))
    print(f"{N:,} random pairs above the surface, float64; load average {load_before:.1f} "
          f"before, {os.getloadavg()[0]:.1f} after, on {os.cpu_count()} cores")
    print(f"{'':34s} {'eval M/s':>9s} {'per CPU-s':>10s} {'sample M/s':>11s} {'per CPU-s':>10s}"
          f" {'eval x mf':>9s}")
    base = rows[0][1][0]
    for name, ev, sa in rows:
        print(f"{name:34s} {ev[0] / 1e6:9.1f} {ev[2] / 1e6:10.1f} {sa[0] / 1e6:11.2f} "
              f"{sa[2] / 1e6:10.2f} {ev[0] / base:9.2f}")
    print("M/s = median wall-clock rate; per CPU-s = per CPU second, all threads; eval x mf = "
          "eval rate over RoughDielectric's in this run")


def albedo_table() -> None:
    print()
    print(f"coated model's albedo table ({len(TABLE_MU)} cosines): build time and white-furnace "
          "error max |a(mu) - table(mu)| over theta_i in "
          f"{', '.join(f'{t:g}' for t in WHITE_THETAS)} rad")
    print(f"{'coat':34s} {'strata':>7s} {'build ms':>9s} {'max error':>10s}")
    for label, coat in (("GGX alpha 0.3, eta 1.5", dict(distribution="ggx", alpha=0.3)),
                        ("GGX alpha 0.05, eta 1.5", dict(distribution="ggx", alpha=0.05)),
                        ("Beckmann alpha 0.6, eta 1.8",
                         dict(distribution="beckmann", alpha=0.6, eta=1.8))):
        sampler = CoatedDiffuse(1.0, **coat).layer
        mu = np.cos(WHITE_THETAS)
        truth = AlbedoTable(sampler, mu=mu, strata=1024).albedo
        for strata in (32, 64, 128, 256):
            t0 = time.perf_counter()
            table = AlbedoTable(sampler, strata=strata)
            ms = 1e3 * (time.perf_counter() - t0)
            print(f"{label:34s} {strata:7d} {ms:9.1f} {np.max(np.abs(table(mu) - truth)):10.1e}")


def albedos() -> None:
    print()
    u = stratified(512)
    print("directional albedo (mean of sample() weights over 512^2 strata) at theta_i = "
          f"{', '.join(f'{t:g}' for t in ALBEDO_THETAS)} rad")
    for sigma in (0.1, 0.3, 0.5, 1.0):
        for variant in ("full", "qualitative"):
            model = OrenNayar(1.0, sigma, variant)
            values = [model.sample(incidence(t), u)[1].mean() for t in ALBEDO_THETAS]
            print(f"Oren-Nayar {variant:11s} rho 1, sigma {sigma:3.1f}: "
                  + " ".join(f"{v:.4f}" for v in values))
    for abg in ((2e-3, 1e-3, 2.0), (0.05, 0.02, 1.5)):
        model = ABg(*abg)
        sums = [model.sample(incidence(t), u)[1].mean() for t in ALBEDO_THETAS]
        tis = [float(model.total_integrated_scatter(incidence(t))) for t in ALBEDO_THETAS]
        print(f"ABg {abg}: sums " + " ".join(f"{v:.5f}" for v in sums)
              + "; closed-form TIS " + " ".join(f"{v:.5f}" for v in tis))


def smooth_surface_limit() -> None:
    print()
    u = stratified(512)
    print("Rayleigh-Rice, sigma 1 nm at 632.8 nm: scatter integral (mean of sample() weights over "
          "512^2 strata) / smooth-surface TIS - 1 at theta_i = "
          f"{', '.join(f'{t:g}' for t in ALBEDO_THETAS)} rad")
    for label, material in (("glass", dict(eta=1.5)), ("Al", dict(eta=1.37, k=7.6))):
        for c in (2.0, 3.0):
            for b in (2.0, 20.0, 200.0):
                model = RayleighRice(1.0, b, c, **material)
                values = [model.sample(incidence(t), u)[1].mean()
                          / float(model.smooth_surface_tis(incidence(t))) - 1.0
                          for t in ALBEDO_THETAS]
                print(f"{label:5s} c {c:3.1f}, b {b:5.0f} um: "
                      + " ".join(f"{v:+.1e}" for v in values))


def picture(path: str) -> None:
    """In-plane f cos_o against the signed viewing angle (negative: toward the source) of one
    model per family, at incidences 30 and 60 degrees, log scale for ABg and Rayleigh-Rice."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels = {
        "Lambert rho 0.8 and Oren-Nayar rho 0.8, sigma 0.5":
            {"Lambert": Lambert(0.8), "Oren-Nayar full": OrenNayar(0.8, 0.5),
             "Oren-Nayar qualitative": OrenNayar(0.8, 0.5, "qualitative")},
        "coated: rho 0.6 under GGX alpha 0.15, eta 1.5":
            {"coated": CoatedDiffuse(0.6, 0.15, 1.5)},
        "ABg": {"A 2e-3, B 1e-3, g 2": ABg(2e-3, 1e-3, 2.0),
                "A 0.05, B 0.02, g 1.5": ABg(0.05, 0.02, 1.5)},
        "Rayleigh-Rice, sigma 1 nm, 632.8 nm": {
            "glass, b 2 um, c 2": RayleighRice(1.0, 2.0, 2.0, eta=1.5),
            "Al, b 20 um, c 3": RayleighRice(1.0, 20.0, 3.0, eta=1.37, k=7.6)},
    }
    view = np.radians(np.linspace(-89.5, 89.5, 719))
    wo = np.stack([np.sin(view), np.zeros_like(view), np.cos(view)], axis=-1)
    fig, axes = plt.subplots(1, 4, figsize=(20, 4.2))
    for ax, (title, models) in zip(axes, panels.items(), strict=True):
        for name, model in models.items():
            for theta, style in ((30, "-"), (60, "--")):
                wi = incidence(math.radians(-theta))  # the source on the negative side
                ax.plot(np.degrees(view), model.eval(wi, wo) * wo[:, 2], style,
                        label=f"{name}, {theta} deg")
        ax.set_title(title, fontsize=10)
        ax.set_xlabel("viewing angle, deg (negative: toward the source)")
        if title.startswith(("ABg", "Rayleigh-Rice")):
            ax.set_yscale("log")
        ax.legend(fontsize=7)
    axes[0].set_ylabel("f cos theta_o, 1/sr")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    print(f"picture: {path}")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--picture", metavar="PNG", help="only draw the families' picture")
    args = parser.parse_args()
    if args.picture:
        picture(args.picture)
    else:
        throughput()
        albedo_table()
        albedos()
        smooth_surface_limit()
