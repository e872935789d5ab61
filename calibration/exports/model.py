"""Exports of a fitted model: Zemax tabular BSDF (`Source Model`), ASTM E1392 on a grid and
Mitsuba 3 material; the fit to export (one of `gonio fit --json`, or fitted here), refused when
its chi-square says it does not describe the data.

Mitsuba's convention, which the export follows with the fitted alpha and index unchanged:
gonio's f(wi = toward the source, wo = toward the detector) is Walter's radiance BTDF, and
Mitsuba 3's `roughdielectric` evaluated in radiance mode with si.wi toward the camera (the
detector's place) and wo toward the light (the source's) gives the same value; with the roles
swapped (the camera on the source's side of the interface) Mitsuba's value is gonio's times
1/eta^2, the BTDF's reciprocity across an index change (f(o, i) / n_i^2 = f(i, o) / n_o^2).
tests/fitting/test_exports_mitsuba.py evaluates Mitsuba itself.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from calibration.exports.astm import side_paths, sides_of
from calibration.exports.family_fit import MICROFACET, FamilyFit, family_fit
from calibration.exports.mitsuba import (
    PLUGIN_TABLES,
    PLUGIN_TYPE,
    PLUGIN_USE,
    material_parameters,
    plugin_material,
    write_mitsuba,
    write_plugin_beside,
)
from calibration.exports.zemax import tabulate, write_zemax
from calibration.fit import FitOptions, FitResult, select
from calibration.fit.result import MAX_CHI2_DOF, worst_chi2_dof
from calibration.reduced import ReducedData
from calibration.smearing import Smearing, smearing_order
from calibration.values import CalibrationError
from drivers.user_file import SETTINGS_FILE_CAP, read_user_text


def fit_notes(result: FitResult, source: str, record: Sequence[str]) -> list[str]:
    """The fit in one line, then the run's record (gonio.record.record_lines)."""
    params = ", ".join(f"{n} = {v:.6g} +- {e:.2g}"
                       for n, v, e in zip(result.names, result.values, result.errors, strict=True))
    held = ("n/a" if result.chi2_dof_heldout is None else f"{result.chi2_dof_heldout:.3g}")
    family = family_fit(result)
    model = (f"{result.distribution} ({result.masking} masking), {params}, eta = "
             f"{result.eta:.6g}" if family is None else f"{family.title()}: {params}")
    return [f"gonio fit of {source}: {model}; chi2/dof fitted {result.chi2_dof_fit:.3g} "
            f"({result.n_fit} points), held out {held} ({result.n_heldout} points)",
            *record]


def point_model(result: FitResult) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    """The fitted model at a point (no aperture average), scale included: f(wi, wo), 1/sr."""
    family = family_fit(result)
    if family is not None:
        return family.point_model()
    model = result.model()

    def f(wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        return result.scale * model.eval(wi, wo)

    return f


def table_grid(result: FitResult, data: ReducedData) -> tuple[float, float, bool, str]:
    """(index, lobe width in degrees, isotropic, the model's name) that size a table of the
    fit's model: the fitted alpha and index; or a family's lobe width (FamilyFit) and the
    data's index (a family reflects only: a BTDF table holds the measured data, or zeros)."""
    family = family_fit(result)
    if family is not None:
        return (float(data.meta.get("eta") or 1.0), family.lobe_width_deg(), True,
                f"the fitted {family.describe()} model")
    alpha = np.atleast_1d(result.alpha)
    return (result.eta, math.degrees(float(alpha.min())), bool(alpha[0] == alpha[-1]),
            f"the fitted {result.distribution} model (alpha "
            f"{', '.join(f'{a:.6g}' for a in alpha)})")


def _zemax_layout(data: ReducedData, result: FitResult, source: str, record: Sequence[str]
                  ) -> tuple[np.ndarray, list[str], list[str]]:
    """(incidence angles, sides, header comments) of a Zemax export of `data`'s fit."""
    theta_i = np.unique(np.round(data.theta_i_deg[data.valid], 3))
    if len(theta_i) == 0:
        raise CalibrationError("zemax: the data have no valid point to take incidences from")
    notes = fit_notes(result, source, record) + [
        "AngleOfIncidence = specular reflection angle (BRDF) or refracted direct-transmission "
        "angle asin(sin(theta_i)/eta) (BTDF); incidence angles theta_i: "
        + " ".join(f"{t:g}" for t in theta_i)]
    return theta_i, sides_of(data.transmission[data.valid]), notes


def zemax_files(data: ReducedData, result: FitResult, out_path: str | Path,
                source: str = "", record: Sequence[str] = ()) -> list[Path]:
    """Tabulate the fitted model (point_model) at the data's incidence angles, `Source
    Model`, on a grid that holds every measured direction: one file per measured side, the
    BTDF at out_path when transmission was measured,
    else the BRDF; the other side goes next to it as <stem>-BRDF<suffix>. `record`: the run's
    record lines, as header comments."""
    from calibration.exports.zemax_measured import measured_nodes

    theta_i, sides, notes = _zemax_layout(data, result, source, record)
    eta, width_deg, isotropic, _ = table_grid(result, data)
    paths = []
    for side, path in zip(sides, side_paths(out_path, sides), strict=True):
        points = data.subset(data.valid & (data.transmission == (side == "BTDF")))
        at = measured_nodes(points, side, eta, isotropic)
        table = tabulate(point_model(result), side, theta_i, eta, width_deg,
                         isotropic=isotropic, comments=notes, nodes=(at.azimuth, at.radial))
        paths.append(write_zemax(table, path))
    return paths


def measured_zemax_files(data: ReducedData, result: FitResult, out_path: str | Path,
                         source: str = "", record: Sequence[str] = ()) -> list[Path]:
    """The measured data as Zemax tables (`Source Measured`, calibration.exports.
    zemax_measured), the fit's point_model filling only where there is no data; files named
    as zemax_files names them."""
    from calibration.exports.zemax_measured import measured_table

    _, sides, notes = _zemax_layout(data, result, source, record)
    eta, width_deg, isotropic, name = table_grid(result, data)
    return [write_zemax(measured_table(data, side, eta, point_model(result), width_deg,
                                       isotropic, notes, name), path)
            for side, path in zip(sides, side_paths(out_path, sides), strict=True)]


def mitsuba_files(result: FitResult, out_path: str | Path, source: str = "",
                  record: Sequence[str] = (), single_scattering: bool = False
                  ) -> tuple[list[Path], list[str]]:
    """The fitted material as a Mitsuba 3 scene fragment (`record`: the run's record lines, as
    comments) and the notes to say: a fit with multiple scattering as the gonio_multiscatter
    plugin (the plugin file beside the XML; refused where it cannot match the model), or with
    `single_scattering` as the single-scattering material with a line saying what it drops."""
    from calibration.exports.mitsuba_energy import dropped_energy_line

    notes = fit_notes(result, source, record)
    family = family_fit(result)
    if family is not None:
        return _family_mitsuba_files(family, out_path, notes)
    if result.distribution == "phong":
        notes.append("Mitsuba 3 has no Phong distribution: written as Beckmann of the same alpha "
                     "(Walter's mapping)")
    if result.masking != "separable":
        notes.append(f"the fit preferred {result.masking} masking; Mitsuba uses separable Smith")
    if result.k is None:
        notes.append("Mitsuba's radiance-mode transmission with the camera in the detector's "
                     "place equals gonio's BTDF (Walter's radiance BTDF); with the camera on the "
                     f"source's side it is 1/eta^2 = {1 / result.eta**2:.6g} of it (reciprocity "
                     "across the index change)")
    material = material_parameters(result.distribution, result.alpha, result.eta, result.scale,
                                   result.k)
    if result.walks is None:
        return [write_mitsuba(material, out_path, notes)], []
    if single_scattering:
        said = dropped_energy_line(result)
        return [write_mitsuba(material, out_path, [*notes, said])], [said]
    material, said = _multiple_scattering_material(result, material)
    path = write_mitsuba(material, out_path, [*notes, *said])
    return [path, write_plugin_beside(path)], []


def _family_mitsuba_files(family: FamilyFit, out_path: str | Path, notes: list[str]
                          ) -> tuple[list[Path], list[str]]:
    """A family fit's Mitsuba material (mitsuba_families.family_material) and, for a plugin
    material, the plugin file beside it."""
    from calibration.exports.mitsuba_families import COATED_TYPE, family_material

    material, said = family_material(family)
    path = write_mitsuba(material, out_path, [*notes, *said])
    return ([path, write_plugin_beside(path)] if material["type"] == COATED_TYPE
            else [path]), []


def _multiple_scattering_material(result: FitResult, single: dict
                                  ) -> tuple[dict, list[str]]:
    """The gonio_multiscatter material around `single` and the notes that say so; a
    CalibrationError where its tables cannot hold the model's R + T within MAX_ALBEDO_ERROR."""
    from calibration.exports import mitsuba_energy as energy

    refusal = ("mitsuba: the fit has multiple scattering, which the material carries only as "
               "the gonio_multiscatter plugin's tables of incidence angle")
    advice = ("; pass --single-scattering to write the single-scattering material, which "
              "drops it (the export says how much)")
    alpha = np.atleast_1d(result.alpha)
    if alpha[0] != alpha[-1]:
        raise CalibrationError(f"{refusal}, which cannot hold an anisotropic surface{advice}")
    comp = energy.compensation(result)
    if comp.worst_error > energy.MAX_ALBEDO_ERROR:
        raise CalibrationError(
            f"{refusal}, and with them R + T is {100 * comp.worst_error:.2g} % from the "
            f"model's at {comp.worst_at_deg:g} deg (more than "
            f"{100 * energy.MAX_ALBEDO_ERROR:g} %){advice}")
    tables = dict(zip(PLUGIN_TABLES, (*comp.added.outside, *comp.added.inside), strict=True))
    return (plugin_material(single, result.eta, comp.added.theta_deg, tables),
            [f"multiple scattering: the {PLUGIN_TYPE} plugin adds the fit's orders >= 2 (and "
             "what Mitsuba's single scattering lacks of the fit's) as cosine lobes of "
             f"tabulated albedo; R + T is within {100 * comp.worst_error:.2g} % of the model's "
             f"at every incidence (worst at {comp.worst_at_deg:g} deg)", PLUGIN_USE])


def result_from_json(fitted: dict, where: str) -> FitResult:
    """The FitResult of a `gonio fit --json` object (its covariance: the parameters'
    variances), of the family its `family` names (the microfacet interface where it names
    none); a CalibrationError names `where` if the object is not one."""
    try:
        family = fitted.get("family") or MICROFACET
        params = fitted["parameters"]
        names = tuple(n for n, p in params.items() if not p.get("fixed")
                      and n != "phong_exponent")
        values = np.array([float(params[n]["value"]) for n in names])
        errors = np.array([float(params[n].get("sigma", 0.0)) for n in names])
        scores = dict(chi2_dof_fit=float(fitted["chi2_dof_fit"]), n_fit=int(fitted["n_fit"]),
                      chi2_dof_heldout=fitted.get("chi2_dof_heldout"),
                      n_heldout=int(fitted.get("n_heldout", 0)),
                      preferred_by=fitted.get("preferred_by_delta_chi2"),
                      candidates=list(fitted.get("candidates", [])))
        if family != MICROFACET:
            return _family_result(fitted, family, names, values, errors, scores, where)
        ms, diffraction = fitted.get("multiple_scattering"), fitted.get("diffraction")
        aperture = float(fitted.get("aperture_half_angle_deg") or 0.0)
        divergence = float(fitted.get("beam_divergence_deg") or 0.0)
        alpha = float(min(v for n, v in zip(names, values, strict=True)
                          if n.startswith("alpha")))
        result = FitResult(
            distribution=fitted["distribution"], masking=fitted["masking"], names=names,
            values=values, errors=errors, covariance=np.diag(errors ** 2),
            eta=float(params["eta"]["value"]),
            k=float(params["k"]["value"]) if "k" in params else None, **scores,
            optics=Smearing(aperture, smearing_order(aperture, alpha), divergence,
                            smearing_order(divergence, alpha)),
            walks=None if ms is None else int(ms["walks"]),
            seed=0 if ms is None else int(ms["seed"]))
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise CalibrationError(f"{where}: not a `gonio fit --json` result ({exc!r})") from None
    if diffraction is not None:
        from calibration.fit import Diffraction

        result.diffraction = Diffraction(**diffraction)
    return result


def _family_result(fitted: dict, family: str, names: tuple[str, ...], values: np.ndarray,
                   errors: np.ndarray, scores: dict, where: str) -> FitResult:
    """The FitResult of a family's `gonio fit --json` object, once its parameters build the
    family's model (a CalibrationError naming `where` and what is wrong otherwise)."""
    result = FitResult(distribution=fitted.get("distribution") or "",
                       masking=fitted.get("masking") or "", names=names, values=values,
                       errors=errors, covariance=np.diag(errors ** 2),
                       eta=float(dict(zip(names, values, strict=True)).get("eta", 1.0)), k=None,
                       family=family, settings=dict(fitted.get("settings") or {}),
                       fixed={n: float(p["value"]) for n, p in fitted["parameters"].items()
                              if p.get("fixed")}, **scores)
    try:
        family_fit(result).model()
    except ValueError as exc:
        raise CalibrationError(f"{where}: the {family} fit does not build its model ({exc})"
                               ) from None
    return result


def load_fit(path: str | Path) -> FitResult:
    """The fit a `gonio fit --json` output file holds (its last JSON line)."""
    path = Path(path)
    text = read_user_text(path, "fit result", SETTINGS_FILE_CAP, CalibrationError)
    try:
        fitted = json.loads([ln for ln in text.splitlines() if ln.strip()][-1])
    except (ValueError, IndexError):
        raise CalibrationError(f"{path}: not the JSON of `gonio fit --json`") from None
    return result_from_json(fitted, str(path))


def check_describes(result: FitResult, force: bool, from_file: bool = False) -> list[str]:
    """Nothing when the fit describes the data (chi2/dof at most MAX_CHI2_DOF, fitted and held
    out); with `force`, the warning to note in the file; else a CalibrationError saying so
    (from_file: the fit came from --fit, so the advice is a better fit, not that option)."""
    worst, which = worst_chi2_dof(result.chi2_dof_fit, result.chi2_dof_heldout)
    if worst <= MAX_CHI2_DOF:
        return []
    name = result.distribution if family_fit(result) is None else result.family
    said = (f"the {name} fit's {which} chi2/dof is {worst:.3g} (above "
            f"{MAX_CHI2_DOF:g}): the model does not describe the data within their "
            "uncertainties")
    if not force:
        better = ("give --fit a better fit (e.g. from gonio fit --json --multiple-scattering)"
                  if from_file else "choose a better fit (fit options such as "
                  "--multiple-scattering, or --fit FIT.json)")
        raise CalibrationError(f"export: {said}; {better} or pass --force")
    return [f"exported although {said} (forced)"]


def fit_for_export(data: ReducedData, options: FitOptions | None, fit_file: str | Path | None,
                   force: bool) -> tuple[FitResult, list[str]]:
    """The fit to export (from `fit_file`, else fitted with `options`: the families the
    sample's kind allows, as `gonio fit` fits) and its notes."""
    result = load_fit(fit_file) if fit_file is not None else select(data, options)
    return result, check_describes(result, force, from_file=fit_file is not None)


def astm_model_tables(data: ReducedData, result: FitResult, notes: Sequence[str]
                      ) -> list:
    """The fitted model (at a point) on a regular grid at the data's incidences, one table per
    measured side: theta_s 0..89 deg by 1, phi_s over the half plane (isotropic) or all
    azimuths by 5."""
    from calibration.exports.astm import AstmTable, sides_of
    from calibration.exports.measured import unit_vectors

    good = data.subset(data.valid)
    incidences = np.unique(np.round(good.theta_i_deg, 3))
    stop = 180.1 if table_grid(result, data)[2] else 360.0
    theta_s, phi_s = (g.ravel() for g in np.meshgrid(np.arange(0.0, 89.5, 1.0),
                                                      np.arange(0.0, stop, 5.0)))
    model = point_model(result)
    wavelength = good.meta.get("wavelength_nm")
    tables = []
    for side in sides_of(good.transmission):
        rows = []
        for ti in incidences:
            wo = unit_vectors(theta_s, phi_s)
            if side == "BTDF":
                wo[:, 2] *= -1.0
            wi = np.broadcast_to(unit_vectors(np.array([ti]), np.array([180.0])), wo.shape)
            rows.append((np.full(len(wo), ti), model(wi, wo)))
        ti_all = np.concatenate([r[0] for r in rows])
        n = len(ti_all)
        tables.append(AstmTable(side, np.radians(ti_all), np.full(n, math.pi),
                                np.radians(np.tile(theta_s, len(incidences))),
                                np.radians(np.tile(phi_s, len(incidences))),
                                [math.nan if wavelength is None else float(wavelength)],
                                np.concatenate([r[1] for r in rows])[:, None],
                                comments=list(notes), source="MODEL"))
    return tables
