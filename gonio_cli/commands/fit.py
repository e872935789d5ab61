"""`gonio fit RUN [--json]`: fit the microfacet model to a run's reduced BSDF (by default at
normal incidence only, as Walter et al. did) and score it on the other incidences; with
--diffraction, the two-scale diffraction model around it. `gonio fit --import FILE` fits a
measured file gonio did not make (calibration.imports)."""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import replace

from calibration.candidates import DISTRIBUTION_NAMES, FAMILIES, MASKINGS
from gonio_cli.commands.reduce import (
    add_angle_option,
    add_reduce_options,
    add_run_or_import,
    imported,
    say_angle_terms,
)


def _list(text: str) -> tuple[str, ...]:
    return tuple(part.strip() for part in text.split(",") if part.strip())


def _angles(text: str) -> tuple[float, ...] | None:
    if text == "all":
        return None
    try:
        return tuple(float(part) for part in _list(text))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected 'all' or degrees like 0,30; got {text!r}") from None


def add_fit_options(p: argparse.ArgumentParser) -> None:
    """The model and subset options `fit` shares with `plot --fit`."""
    p.add_argument("--distribution", type=_list, default=DISTRIBUTION_NAMES,
                   metavar="D[,D...]",
                   help=f"candidates: {', '.join(DISTRIBUTION_NAMES)} (default: all)")
    p.add_argument("--masking", type=_list, default=("separable",), metavar="M[,M...]",
                   help=f"candidates: {', '.join(MASKINGS)} (default: separable)")
    p.add_argument("--anisotropic", action="store_true", help="fit alpha_x and alpha_y")
    p.add_argument("--fit-eta", action="store_true", help="fit eta too (else fixed)")
    p.add_argument("--fit-scale", action="store_true", help="fit an overall scale factor")
    p.add_argument("--eta", type=float, help="eta (default: the run's sample eta)")
    p.add_argument("--incidence", type=_angles, default=(0.0,), metavar="DEG[,DEG...]|all",
                   help="incidence angles of the fitted subset (default 0; 'all' for every point)")
    p.add_argument("--multiple-scattering", action="store_true",
                   help="add the random walk's orders >= 2 to the model (a deterministic "
                        "table in alpha, fixed seed; its Monte Carlo error joins sigma)")
    p.add_argument("--ms-walks", type=int, default=1 << 17, metavar="N",
                   help="walks per incidence angle and table alpha for --multiple-scattering "
                        "(default 131072, at most 4194304; the fitted term at the result walks "
                        "4x as many: about 1 s on a Walter run at the default, in proportion "
                        "to N)")
    p.add_argument("--diffraction", action="store_true",
                   help="fit the two-scale diffraction model (Holzschuch-Pacanowski) around the "
                        "microfacet one, at the run's wavelength; nano-roughness held fixed")
    p.add_argument("--rms-height-nm", type=float, metavar="NM",
                   help="nano-roughness rms height for --diffraction (required, but for a run "
                        "whose devices were all emulated: its [sim.sample] rms_height_nm)")
    p.add_argument("--correlation-length-um", type=float, metavar="UM",
                   help="nano-roughness correlation length for --diffraction (required, but "
                        "for an all-emulated run: its [sim.sample] correlation_length_um)")
    p.add_argument("--psd-exponent", type=float, metavar="C",
                   help="K-correlation PSD exponent for --diffraction (default 2, or an "
                        "all-emulated run's [sim.sample] psd_exponent)")
    add_reduce_options(p)
    add_angle_option(p)


def nano_roughness(sim: dict | None, rms_height_nm: float | None,
                   correlation_length_um: float | None,
                   psd_exponent: float | None) -> tuple[float | None, float | None, float]:
    """(rms height nm, correlation length um, PSD exponent) for --diffraction: each flag given
    wins, else the [sim.sample] value of `sim` (the [sim] table of an all-emulated run,
    gonio.record.emulator_config; None for any other run), else None (the exponent: 2)."""
    sample = (sim or {}).get("sample") or {}
    given = (rms_height_nm, correlation_length_um, psd_exponent)
    keys = ("rms_height_nm", "correlation_length_um", "psd_exponent")
    rms, length, exponent = (value if value is not None else sample.get(key)
                             for value, key in zip(given, keys, strict=True))
    return (None if rms is None else float(rms), None if length is None else float(length),
            2.0 if exponent is None else float(exponent))


def options_from(args: argparse.Namespace,
                 sim: dict | None = None):  # -> calibration.fit.FitOptions
    """FitOptions from parsed arguments; `sim` (an all-emulated run's [sim] table) supplies
    the nano-roughness of --diffraction that no flag gives."""
    from calibration.fit import FitOptions

    rms, length, exponent = nano_roughness(sim, args.rms_height_nm,
                                           args.correlation_length_um, args.psd_exponent)
    return FitOptions(distributions=args.distribution, maskings=args.masking,
                      anisotropic=args.anisotropic, fit_eta=args.fit_eta,
                      fit_scale=args.fit_scale, eta=args.eta,
                      fit_incidence_deg=args.incidence,
                      multiple_scattering=args.multiple_scattering, ms_walks=args.ms_walks,
                      diffraction=args.diffraction, rms_height_nm=rms,
                      correlation_length_um=length, psd_exponent=exponent)


def emulator_sim(run_dir: str) -> dict | None:
    """The [sim] table of a run whose devices were all emulated, else None."""
    from gonio.record import emulator_config
    from gonio.store import open_run

    return emulator_config(open_run(run_dir))


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the `fit` verb."""
    p = subparsers.add_parser("fit", help="fit the BSDF model to a run", description=__doc__)
    add_run_or_import(p)
    p.add_argument("--json", action="store_true", help="print the result as one JSON object")
    p.add_argument("--family", type=_list, metavar="NAME[,NAME...]",
                   help=f"the model families compared: {', '.join(FAMILIES)} (default: those "
                        "the sample's kind allows: hemisphere, slab, conductor the microfacet "
                        "interface alone; diffuse, coated and reference their matte families; "
                        "an imported file of no kind all of them)")
    p.add_argument("--relative", action="store_true",
                   help="the data are known up to a scale (relative to a reference): fit a "
                        "free scale factor, reported with its uncertainty")
    add_fit_options(p)
    p.set_defaults(func=run, reads_run="run")


def run(args: argparse.Namespace) -> int:
    """Fit and print the result (a summary, or one JSON object with --json: the fit, the data's
    facts, their uncertainty budget (calibration.budget.summary), the run's completeness
    (gonio.completeness; None for an imported file) and the warnings)."""
    from calibration.budget import summary as budget_summary
    from calibration.fit import select
    from calibration.pipeline import fit_run
    from gonio.store import open_run

    data = imported(args)
    if data is None:
        sim = emulator_sim(args.run) if args.diffraction else None
        data, result = fit_run(open_run(args.run, force=args.force),
                               _selection(options_from(args, sim), args), args.calibration,
                               args.shot_noise_w, args.subtract_signature, progress=_to_stderr,
                               angle_terms=not args.no_angle_terms)
        say_angle_terms(args)
    else:
        result = select(data, _selection(options_from(args), args), _to_stderr)
    out = result.to_dict()
    out["run"] = str(args.run if data.meta.get("imported_from") is None else
                     data.meta["imported_from"])
    out["sample"] = data.meta.get("sample")
    out["calibration"] = data.meta.get("calibration")
    out["noise_model"] = data.meta.get("noise_model")
    out["completeness"] = data.meta.get("completeness")  # a run's (gonio.completeness)
    out["budget"] = budget_summary(data)
    if data.meta.get("emulator_truth"):
        out["emulator_truth"] = data.meta["emulator_truth"]
    out["warnings"] = fit_warnings(out, imported_from=data.meta.get("imported_from"))
    if args.json:
        for line in out["warnings"]:
            print(f"gonio fit: {line}", file=sys.stderr)
        print(json.dumps(out))
        return 0
    print(summary(out))
    return 0


def _selection(options, args: argparse.Namespace):  # -> calibration.fit.FitOptions
    """The options with `fit`'s own flags: the families compared (--family) and a free scale
    (--relative)."""
    return replace(options, families=args.family,
                   fit_scale=options.fit_scale or args.relative)


def fit_warnings(out: dict, imported_from: str | None = None, plotted: bool = False
                 ) -> list[str]:
    """Warnings of a fit result dict: a chi2/dof (fitted or held out) above the limit model
    exports refuse at (calibration.exports.model.MAX_CHI2_DOF), and the likely cause; they
    point to `gonio plot RUN --fit` unless the fit is of an imported file or being plotted."""
    from calibration.fit.result import MAX_CHI2_DOF, worst_chi2_dof

    worst, _ = worst_chi2_dof(out["chi2_dof_fit"], out["chi2_dof_heldout"])
    if worst <= MAX_CHI2_DOF:
        return []
    look = "" if imported_from or plotted else f" (see gonio plot {out['run']} --fit)"
    lines = [f"warning: chi2/dof {worst:.3g} is well above 1: the model does not describe the "
             f"points within their uncertainties{look}; model exports refuse this fit"]
    if out.get("residual_pattern") is not None:
        return lines + residual_hints(out)
    if _rough_single_scattering(out) is not None:
        lines.append(_multiple_scattering_hint(out))
    return lines


#: Families with a lobe about the specular direction, and with a diffuse term (residual_hints).
LOBED = ("microfacet", "lambert+microfacet", "abg", "rayleigh-rice")
DIFFUSE = ("lambert", "oren-nayar", "lambert+microfacet")


def residual_hints(out: dict) -> list[str]:
    """Hints of a bad fit from where its residuals lie (calibration.fit.pattern): a diffuse
    floor suggests a diffuse term (multiple scattering when a rough microfacet fit's floor is
    not flat, diffraction when a polished one's is not), an excess on the source's side beyond
    any floor Oren-Nayar (unless the lobe's shape is off, whose tails lift it too), a lobe of
    the wrong width another distribution, a peak over a model without a lobe a lobe."""
    pattern, family = out["residual_pattern"], out.get("family", "microfacet")
    hints = []
    if pattern["floor"] > 0 and family not in DIFFUSE:
        if not pattern["floor_flat"] and _rough_single_scattering(out) is not None:
            hints.append(_multiple_scattering_hint(out))
        elif not pattern["floor_flat"] and _smooth_without_diffraction(out) is not None:
            hints.append(f"hint: at alpha {_smooth_without_diffraction(out):.3g} the data's "
                         "floor falls away from the specular direction, as a polished "
                         "surface's nano-roughness halo does: try --diffraction")
        else:
            hints.append(f"hint: the data lie above the {family} model far from the specular "
                         "direction (a diffuse floor): add a diffuse term, try --family "
                         "lambert+microfacet")
    if pattern["retro"] > max(pattern["floor"], 0.0) and not pattern["lobe"] \
            and family != "oren-nayar":
        hints.append("hint: the data lie above the model on the source's side (back-scatter "
                     "of a rough matte surface): try --family oren-nayar")
    if pattern["lobe"] and family in LOBED:
        width = "wider" if pattern["lobe"] > 0 else "narrower"
        hints.append(f"hint: the model's lobe is {width} than the data's about the specular "
                     "direction: its shape is another distribution's, try --distribution "
                     "with the others")
    elif pattern["peak"] > 0 and family not in LOBED:
        hints.append(f"hint: the data peak about the specular direction, which {family} does "
                     "not: add a specular lobe, try --family lambert+microfacet")
    return hints


def _microfacet_alpha(out: dict, without: str) -> float | None:
    """The largest alpha of a microfacet fit made without the term `without` names
    ("multiple_scattering", "diffraction"), else None."""
    if out.get("family", "microfacet") != "microfacet" or out.get(without):
        return None
    return max(p["value"] for name, p in out["parameters"].items() if name.startswith("alpha"))


def _rough_single_scattering(out: dict) -> float | None:
    """The largest alpha of a microfacet fit without multiple scattering above ROUGH_ALPHA,
    else None."""
    alpha = _microfacet_alpha(out, "multiple_scattering")
    return alpha if alpha is not None and alpha > ROUGH_ALPHA else None


def _smooth_without_diffraction(out: dict) -> float | None:
    """The largest alpha of a microfacet fit without the diffraction term below SMOOTH_ALPHA
    (a polished surface, whose halo is diffraction), else None."""
    alpha = _microfacet_alpha(out, "diffraction")
    return alpha if alpha is not None and alpha < SMOOTH_ALPHA else None


def _multiple_scattering_hint(out: dict) -> str:
    return (f"hint: at alpha {_rough_single_scattering(out):.3g} light scatters more than once "
            "between microfacets, which single scattering leaves out: try "
            "--multiple-scattering")


def _to_stderr(line: str) -> None:
    """A fit's progress line, on stderr (stdout keeps the result alone)."""
    print(f"gonio {line}", file=sys.stderr, flush=True)


#: Above this alpha, multiple scattering is a visible part of a rough dielectric's lobe.
ROUGH_ALPHA = 0.1
#: Below this alpha a surface is polished: a halo beside its lobe is diffraction's.
SMOOTH_ALPHA = 0.05


def chi2_lines(out: dict) -> list[str]:
    """The chosen fit's chi2/dof (fitted, held out) and every candidate's as it was ranked,
    the chosen one's refit beside it: with multiple scattering the candidates are ranked with
    their term walked ms_walks times and the chosen one refitted with it walked fitted_walks
    times (calibration.fit), so the refit is the figure the fit line gives."""
    ms = out.get("multiple_scattering")
    held = out["chi2_dof_heldout"]
    walked = (f", multiple scattering by {ms.get('fitted_walks', ms['walks'])} walks"
              if ms else "")
    fitted = (f"  chi2/dof fitted {out['chi2_dof_fit']:.3g} ({out['n_fit']} points{walked}); "
              "held out " + ("n/a" if held is None else f"{held:.3g} ({out['n_heldout']} points)"))
    verdict = ("clearly preferred" if out["clearly_preferred"]
               else "not distinguishable from the runner-up")
    if out.get("criterion"):
        return [fitted, *family_lines(out), f"  -> {out['family']} by {out['criterion']}, "
                f"{verdict}"]
    others = ", ".join(f"{c['distribution']}/{c['masking']} {c['chi2_dof_fit']:.3g}"
                       + (f" (refit {c['chi2_dof_refit']:.3g})" if "chi2_dof_refit" in c else "")
                       for c in out["candidates"] if "distribution" in c)
    ranked = f" fitted as ranked (multiple scattering by {ms['walks']} walks)" if ms else " fitted"
    return [fitted, f"  candidates chi2/dof{ranked}: {others} -> {verdict}"]


def model_name(entry: dict) -> str:
    """A fit's or candidate's model as the summary names it: the family with its settings
    (`lambert+microfacet/ggx/separable`), or the microfacet distribution and masking."""
    if entry.get("family", "microfacet") == "microfacet":
        return f"microfacet/{entry['distribution']}/{entry['masking']}"
    return "/".join([entry["family"], *map(str, entry.get("settings", {}).values())])


def family_lines(out: dict) -> list[str]:
    """One line per candidate of a family selection, best first: its BIC, chi2/dof fitted
    and held out, and its parameters."""
    lines = [f"  candidates by {out['criterion']} (chi2 + k ln n on the fitted points):"]
    for c in out["candidates"]:
        if "failed" in c:
            continue
        held = c["chi2_dof_heldout"]
        params = ", ".join(f"{n} {p['value']:.4g} +- {p['sigma']:.2g}"
                           for n, p in c["parameters"].items())
        lines.append(f"    {model_name(c):<36} {out['criterion']} {c['bic']:.5g}  chi2/dof "
                     f"{c['chi2_dof_fit']:.3g}, held out "
                     + ("n/a" if held is None else f"{held:.3g}") + f"  ({params})")
    return lines


def summary(out: dict) -> str:
    """Human-readable lines of a fit result dict."""
    sample = out.get("sample")
    eta = f", eta {sample['eta']:g}" if sample and sample["eta"] is not None else ""
    measured = f" sample {sample['id']} ({sample['kind']}{eta}):" if sample else ""
    model = (f"{out['distribution']} ({out['masking']} masking)"
             if out.get("family", "microfacet") == "microfacet" else model_name(out))
    lines = [f"run {out['run']}:{measured} {model}"]
    if out.get("completeness") and not out["completeness"]["complete"]:
        from gonio.completeness import Completeness

        lines.append(f"  {Completeness.from_json(out['completeness']).text()}")
    for name, p in out["parameters"].items():
        fixed = " (fixed)" if p.get("fixed") else ""
        sigma = f" +- {p['sigma']:.3g}" if "sigma" in p and not p.get("fixed") else ""
        lines.append(f"  {name:<15} {p['value']:.6g}{sigma}{fixed}")
    lines += chi2_lines(out)
    lines += [f"  skipped: {c['failed']}" for c in out["candidates"] if "failed" in c]
    lines += [f"  {line}" for line in out.get("warnings", [])]
    if out.get("multiple_scattering"):
        ms = out["multiple_scattering"]
        fitted = ms.get("fitted_walks", ms["walks"])
        lines.append(f"  multiple scattering: orders >= 2 by {fitted} random walks per "
                     f"incidence at the fitted points ({ms['walks']} for predictions), seed "
                     f"{ms['seed']}")
    if out.get("diffraction"):
        d = out["diffraction"]
        lines.append(f"  diffraction: two-scale model, rms height {d['rms_height_nm']:g} nm, "
                     f"correlation length {d['correlation_length_um']:g} um, PSD exponent "
                     f"{d['psd_exponent']:g}, at {d['wavelength_nm']:g} nm (held fixed)")
    if "fit_time_s" in out:
        lines.append(f"  fit time {out['fit_time_s']:.2f} s")
    if out.get("noise_model"):
        lines.append(f"  noise: {out['noise_model']}")
    if out.get("emulator_truth"):
        t = out["emulator_truth"]
        if "family" in t:  # a model family's sample: its parameters and settings by name
            lines.append(f"  emulator truth ([sim.sample]): family {t['family']}, "
                         + ", ".join(f"{k} {v:g}" if isinstance(v, float) else f"{k} {v}"
                                     for k, v in t.items() if k != "family"))
        else:
            lines.append(f"  emulator truth ([sim.sample]): {t['distribution']} alpha "
                         f"{t['alpha']}, eta {t['eta']:g}, {t['masking']} masking")
        if "single_scattering_alpha" in t:
            u = t.get("single_scattering_alpha_u")
            lines.append(f"  alpha {t['alpha']} is the microsurface's, under multiple scattering; "
                         "the default single-scattering fit (normal incidence) of this bench "
                         f"returns {t['single_scattering_alpha']:g}"
                         + ("" if u is None else f" +- {u:g}"))
    return "\n".join(lines)
