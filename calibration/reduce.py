"""Raw detector readings -> BSDF values with 1-sigma uncertainties (`gonio reduce RUN`).

f = (P - dark) / (Phi(t) * Omega * factor * |cos o|): dark subtraction per range from the run's
dark readings, the beam power Phi from the straight-through (beam) readings (a polynomial in
time through all of them, at least a line, calibration.beam), the aperture solid angle Omega,
and the faces the light crosses (`factor`: the hemisphere's T_exit on the transmitted side, as
the bench applies it, model.optics.exit_face.exit_view). Noise of a reading: the scatter of the dark
readings on its range, scaled with the range's full scale (read noise and ADC steps scale so),
plus the signal's shot noise where something states it (`optics_of`: the --shot-noise-w flag,
the config's [detector] shot_noise_w, or the emulated meter of an all-emulated run; otherwise
it is not modelled, and meta["noise_model"] says so); the dark level's uncertainty is
propagated, and the beam curve's, which all points share, both into sigma and as
ReducedData.shared_rel (the fit's covariance). Signature readings (the bench without the sample)
flag, and on request subtract, what the bench adds (calibration.signature). Every such term is
a named component of the value's GUM budget (ReducedData.components, calibration.budget), with
the type-B ones (the calibration's range gains and solid angle, else the config's or the device
kinds' declared figures and the aperture's tolerance: calibration.type_b; the detector's
non-linearity; a reference calibration's effective solid angle replaces the aperture's, and its
certificate's and reference run's errors the solid angle's: calibration.reference) and the
angle errors through a fitted model's slope (docs/fitting.md, "Uncertainty budget")."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from calibration.aperture import solid_angle_sr
from calibration.beam import beam_power
from calibration.budget import (
    COVERAGE_K,
    STAGE_ROLES,
    AngleInputs,
    Budget,
    add_angle_terms,
    move_ids,
    stage_slopes,
)
from calibration.dark import DarkModel
from calibration.detector import range_key
from calibration.emulator_truth import EmulatorTruth, run_config_errors, truth_of
from calibration.reduced import ReducedData
from calibration.reference import COMPONENTS
from calibration.signature import DEFAULT_SHARE, apply_signature
from calibration.type_b import detector_figures, solid_angle_figure
from calibration.values import CalibrationError
from gonio.errors import GonioError
from gonio.geometry import sample_angles
from gonio.optics import Optics, optics_of_config
from gonio.reading_flags import INVALID, flagged
from gonio.sample import SampleInfo, sample_of_plan
from model.optics.exit_face import SampleFaces, exit_view

# A net signal below this many sigmas is dark-limited (valid = False). The cut selects on the
# measured value, so it keeps the noise-only points that fluctuate above it, each with a pull
# beyond the cut: at 3 sigma 0.13 % of them (about one in an anti-glare run's ~500, adding ~0.5
# to the chi-square per dof of its 20-point fit); at 5 sigma 3e-7.
DARK_LIMIT_SIGMAS = 5.0
#: Flag of a point whose aperture reaches across the sample's horizon or whose sample is edge-on.
HORIZON = "horizon"
EDGE_ON_COS = 1e-6  # |cos theta_i| below this: the beam grazes the sample (it is retracted)


#: The fitted model of a reading, f(wi, wo) in 1/sr (FitResult.predict).
SlopeModel = Callable[[np.ndarray, np.ndarray], np.ndarray]

#: The noise model of a run whose shot noise nothing states.
SHOT_NOT_MODELLED = ("dark scatter per range; shot noise not modelled (give [detector] "
                     "shot_noise_w or --shot-noise-w)")


@dataclass(frozen=True)
class ReductionOptics:
    """What reduction takes from a run's description: the sample ([sample]), the aperture's
    half-angle (a calibration's, else [optics]) and where it came from, the wavelength, the
    shot noise of one reading per watt of net signal and the noise model in words, the
    detector's relative 1-sigma non-linearity and range-gain error, the aperture solid angle's
    relative 1-sigma from its tolerance (calibration.type_b; 0: not stated) and `sources`,
    where each of those comes from; `sim` and `truth` are the emulator's [sim] table and its
    sample of an all-emulated run (for plots)."""

    sample: SampleInfo
    aperture_half_angle_deg: float
    aperture_from: str
    wavelength_nm: float
    optics: Optics | None = None
    shot_variance_per_w: float = 0.0
    noise_model: str = SHOT_NOT_MODELLED
    linearity_rel: float = 0.0
    sim: dict | None = None
    truth: dict | None = None
    range_gain_rel: float = 0.0
    solid_angle_rel: float = 0.0
    sources: dict[str, str] = field(default_factory=dict)

    @property
    def aperture_sr(self) -> float:
        """Aperture solid angle."""
        return solid_angle_sr(math.radians(self.aperture_half_angle_deg))


def optics_of(config: dict, cal=None, plan: dict | None = None, sim: dict | None = None,
              shot_noise_w: float | None = None) -> ReductionOptics:
    """What reduction needs, from what the experimenter describes: the run config's [optics]
    (aperture, wavelength) and [detector] (averaging, shot noise), the plan's [sample] (kind,
    eta, k, lit side), a calibration (its aperture wins over [optics]; a measured one's sigma
    over the tolerance, `measured_aperture`) and the --shot-noise-w flag. `sim`: the [sim]
    table of an all-emulated run (gonio.record.emulator_config), the only way the emulator's
    truth comes in (by calibration.emulator_truth): its meter's shot noise when nothing else
    states one, and its sample for plots."""
    try:
        optics = optics_of_config(config, "run config")
        sample = sample_of_plan(plan or {}, "run plan")
    except GonioError as exc:
        raise CalibrationError(str(exc)) from None
    missing = []
    if sample is None:
        missing.append("the plan's [sample] table (id, kind, eta: what was measured)")
    calibrated_aperture = cal is not None and cal.aperture_half_angle_deg is not None
    if optics is None and not calibrated_aperture:
        missing.append("the instrument config's [optics] table (aperture_diameter_mm, "
                       "aperture_distance_mm, wavelength_nm, ...) or a calibration with the "
                       "aperture (gonio calibrate build --aperture-geometry | --aperture-scan)")
    if missing:
        raise CalibrationError(f"cannot reduce: the run lacks {' and '.join(missing)}")
    half_angle, aperture_from = ((cal.aperture_half_angle_deg.value, "calibration")
                                 if calibrated_aperture
                                 else (optics.aperture_half_angle_deg, "[optics]"))
    detector = config.get("detector", {})
    wavelength = (optics.wavelength_nm if optics is not None
                  else float(detector.get("wavelength_nm", math.nan)))
    averaging = int((plan or {}).get("averaging") or detector.get("averaging", 1))
    truth = truth_of(sim, None, (plan or {}).get("sample"))
    variance, noise_model = _shot_noise(detector, truth, shot_noise_w, wavelength, averaging)
    figures = detector_figures(config)
    if optics is not None and not measured_aperture(cal):
        figures["solid_angle"] = solid_angle_figure(optics)
    value = {name: f.sigma for name, f in figures.items()}
    return ReductionOptics(sample, half_angle, aperture_from, wavelength, optics, variance,
                           noise_model, value.get("linearity_rel", 0.0), sim,
                           truth.sample if truth is not None else None,
                           value.get("range_gain_rel", 0.0), value.get("solid_angle", 0.0),
                           {name.removesuffix("_rel"): f.source for name, f in figures.items()})


def _shot_noise(detector: dict, truth: EmulatorTruth | None, shot_noise_w: float | None,
                wavelength_nm: float, averaging: int) -> tuple[float, str]:
    """(shot-noise variance of one reading per watt of net signal, the noise model in words):
    the per-sample coefficient of the --shot-noise-w flag, else of [detector] shot_noise_w,
    else (all-emulated runs only) of the emulated meter, divided by the samples averaged."""
    if shot_noise_w is not None:
        if not (math.isfinite(shot_noise_w) and shot_noise_w >= 0):
            raise CalibrationError(f"--shot-noise-w must be a finite number >= 0 (W per W of "
                                   f"signal), got {shot_noise_w!r}")
        coefficient, source = float(shot_noise_w), "--shot-noise-w"
    elif detector.get("shot_noise_w") is not None:
        coefficient, source = float(detector["shot_noise_w"]), "[detector] shot_noise_w"
    elif truth is not None:
        with run_config_errors():
            coefficient = truth.shot_noise_w(wavelength_nm)
        source = "the emulated meter's [sim.detector] (2 q B / R)"
    else:
        return 0.0, SHOT_NOT_MODELLED
    return coefficient / averaging, (f"dark scatter per range; shot noise {coefficient:.4g} W "
                                     f"per W of signal per sample from {source}, averaged "
                                     f"over {averaging}")


def directions(theta_deg: np.ndarray, phi_deg: np.ndarray, flipped: bool) -> np.ndarray:
    """Unit vectors (N, 3) of sample-frame spherical angles; `flipped` turns them into the frame
    of a sample mounted the other way round (lit through the hemisphere: x, z change sign)."""
    t, p = np.radians(theta_deg), np.radians(phi_deg)
    w = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=-1)
    return w * np.array([-1.0, 1.0, -1.0]) if flipped else w


def reduce_readings(run, readings: np.ndarray, cal=None, optics: ReductionOptics | None = None,
                    subtract_signature: bool = False, signature_share: float = DEFAULT_SHARE,
                    angle: AngleInputs | None = None, slope_model: SlopeModel | None = None
                    ) -> ReducedData:
    """ReducedData of a run's readings (raw, or already corrected by a calibration `cal`), with
    their uncertainty budget (calibration.budget) in `components`, combined into `sigma`.

    run: a gonio.store.Run (its description gives the optics unless `optics` is given, its
    config the stages' repeatability unless `angle` is given). slope_model(wi, wo): the fitted
    model of a reading (FitResult.predict), whose slope carries the angle errors into the
    values; None: the angle terms are left out and meta["budget"] says so.
    Readings flagged invalid (the detector had none) are left out; signature_share,
    subtract_signature: calibration.signature.apply_signature."""
    from gonio.record import emulator_config

    readings = readings[~flagged(readings, INVALID)]
    optics = optics or optics_of(run.config, cal, run.plan, emulator_config(run))
    angle = angle if angle is not None else AngleInputs.of_run(getattr(run, "config", {}), cal)
    kinds = readings["kind"]
    dark = DarkModel.from_readings(readings[(kinds == "dark") & ~readings["saturated"]])
    beam_rows = readings[(kinds == "beam") & ~readings["saturated"]]
    if len(beam_rows) == 0:
        raise CalibrationError("no unsaturated beam readings (kind 'beam') to normalise by")
    b_level, _, b_noise = dark.at(beam_rows["range_w"])
    beam = beam_power(beam_rows["t_s"], beam_rows["power_w"] - b_level, float(np.mean(b_noise)))

    rows = readings[kinds == "sample"]
    sample = optics.sample
    flipped = sample.lit_from == "hemisphere"
    wi = directions(rows["theta_i_deg"], rows["phi_i_deg"], flipped)
    wo = directions(rows["theta_o_deg"], rows["phi_o_deg"], flipped)
    w_eval, factor = exit_view(sample, wi, wo)
    level, level_sigma, read = dark.at(rows["range_w"])
    phi, _, phi_shared = beam.smooth(rows["t_s"])
    net = rows["power_w"] - level
    shot = optics.shot_variance_per_w
    shot_w = np.sqrt(shot * np.maximum(net, 0.0))
    noise = np.hypot(read, shot_w)
    scale = phi * reduction_solid_angle_sr(cal, optics) * factor * np.abs(wo[:, 2])
    signature = apply_signature(readings, rows, dark, beam, shot, net, noise, scale,
                                signature_share, subtract_signature)
    net = signature.net_w
    with np.errstate(divide="ignore", invalid="ignore"):
        per_w = np.where(scale > 0, 1.0 / scale, np.nan)
        bsdf = net * per_w
    budget = Budget(bsdf)
    budget.add_own("read_noise", read * per_w)
    if shot > 0:
        budget.add_own("shot_noise", shot_w * per_w)
    if subtract_signature:
        budget.add_own("signature", np.sqrt(np.maximum(signature.noise_w**2 - noise**2, 0.0))
                       * per_w)
    budget.add_shared("dark", per_range(rows["range_w"], level_sigma * per_w))
    budget.add_shared("beam_normalisation", np.abs(bsdf)[:, None] * phi_shared / phi[:, None])
    sources: dict[str, str] = {}
    notes = calibration_terms(budget, cal, rows["range_w"], beam_rows["range_w"], optics,
                              sources)
    if angle.any and slope_model is None:
        notes.append("angle: not propagated (no fitted model gave the BSDF's slope)")
    elif angle.any:
        angle_terms(budget, readings, rows, angle, slope_model, sample, flipped)
        sources.update(angle_sources(angle))
        if not angle.offset_sigma_deg:
            notes.append("angle_offset: no calibration of the stage zeros applied (the "
                         "config's zeros taken as exact)")
    sigma = budget.sigma
    # an aperture across the sample's horizon, or a sample edge-on to the beam, measures no
    # BSDF (|cos o| -> 0 makes any stray power a huge value): flagged, and the planned side kept
    horizon = ((np.abs(wo[:, 2]) < math.sin(math.radians(optics.aperture_half_angle_deg)))
               | (np.abs(wi[:, 2]) < EDGE_ON_COS))
    valid = (~rows["saturated"] & (scale > 0) & (net > DARK_LIMIT_SIGMAS * signature.noise_w)
             & np.isfinite(bsdf) & ~signature.invalid & ~horizon)
    transmission = np.where(horizon, rows["side"] == "transmission",
                            (wo[:, 2] > 0) != (wi[:, 2] > 0))
    flags = np.array([",".join(f for f in (why, HORIZON if edge else "") if f)
                      for why, edge in zip(signature.flags, horizon, strict=True)], dtype=object)
    meta = {
        "eta": sample.eta, "k": sample.k, "kind": sample.kind, "lit_from": sample.lit_from,
        "sample": sample.to_json(),
        "optics": optics.optics.to_json() if optics.optics is not None else None,
        "wavelength_nm": optics.wavelength_nm,
        "aperture_half_angle_deg": optics.aperture_half_angle_deg,
        "aperture_sr": optics.aperture_sr, "aperture_from": optics.aperture_from,
        "noise_model": optics.noise_model, "shot_variance_per_w": optics.shot_variance_per_w,
        "run": str(getattr(run, "path", "")),
        "beam_mean_w": beam.mean_w, "beam_drift_rms": beam.drift_rms,
        "dark_level_w": {f"{r:.6g}": v for r, v in dark.level.items()},
        "sim": optics.sim, "emulator_truth": optics.truth,
        "side": rows["side"].tolist(), "repeat": rows["repeat"].tolist(),
        "index": rows["index"].tolist(),  # the reading each point comes from
        "coverage_k": COVERAGE_K,
        "budget": {"own": sorted(budget.own), "shared": sorted(budget.shared),
                   "angle_inputs": angle.to_json(), "sources": sources, "notes": notes},
    }
    if signature.meta is not None:
        meta["signature"] = signature.meta
    if cal is not None and cal.reference is not None:
        meta["reference"] = cal.reference.to_json()
    return ReducedData(wi, w_eval, bsdf, sigma, valid, transmission, meta,
                       budget.shared_rel, flags.astype(str), budget.components)


def angle_terms(budget: Budget, readings: np.ndarray, rows: np.ndarray, angle: AngleInputs,
                slope_model: SlopeModel, spec: SampleFaces, flipped: bool) -> None:
    """The stages' errors through the model's slope (calibration.budget.add_angle_terms): the
    derivative of what reduction would give, the model's reading f T |cos o| at the stages'
    positions over T |cos o| at the recorded ones (an angle error moves the reading, not the
    divisor)."""
    def reading(at: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        """(the model's reading before division by T |cos o|, T |cos o|) at stage positions."""
        a = sample_angles(at["sample"], at["arm"], at["elevation"], at["azimuth"])
        wi = directions(a.theta_i_deg, a.phi_i_deg, flipped)
        wo = directions(a.theta_o_deg, a.phi_o_deg, flipped)
        w_eval, factor = exit_view(spec, wi, wo)
        divisor = factor * np.abs(wo[:, 2])
        return slope_model(wi, w_eval) * divisor, divisor

    stages = {role: rows[f"{role}_deg"] for role in STAGE_ROLES}
    _, divisor = reading(stages)
    with np.errstate(divide="ignore", invalid="ignore"):
        per_divisor = np.where(divisor > 0, 1.0 / divisor, np.nan)
    slopes = stage_slopes(stages, set(angle.repeatability_deg) | set(angle.offset_sigma_deg),
                          lambda at: reading(at)[0])
    moves = {role: move_ids(readings, rows, role) for role in angle.repeatability_deg}
    add_angle_terms(budget, {r: s * per_divisor for r, s in slopes.items()}, angle, moves)


def per_range(range_w: np.ndarray, values: np.ndarray) -> np.ndarray:
    """(N, ranges) columns: each point's value in its range's column, 0 elsewhere (an error
    common to the readings of one range)."""
    ranges = np.unique(range_w)
    return np.where(range_w[:, None] == ranges[None, :], values[:, None], 0.0)


def range_columns(range_w: np.ndarray, beam_range_w: np.ndarray,
                  gain_rel: Callable[[float], float] | None = None) -> np.ndarray:
    """(N, ranges) coefficients of each range's own gain error in a value: +1 on the range it
    was read on, minus the share of the beam readings taken on each range (the value is a
    ratio to the beam's; a range both share cancels), times the range's relative 1-sigma gain
    error gain_rel(full scale) (None: 1); columns that are 0 everywhere are left out."""
    ranges = np.union1d(range_w, beam_range_w)
    share = np.array([np.mean(beam_range_w == r) for r in ranges])
    scale = np.ones(len(ranges)) if gain_rel is None else np.array([gain_rel(r) for r in ranges])
    columns = ((range_w[:, None] == ranges[None, :]) - share[None, :]) * scale[None, :]
    return columns[:, np.any(columns != 0, axis=0)]


def angle_sources(angle: AngleInputs) -> dict[str, str]:
    """Where the angle terms' inputs come from, by component (meta["budget"]["sources"])."""
    out = {}
    roles_of: dict[str, list[str]] = {}
    for role in angle.repeatability_deg:
        roles_of.setdefault(angle.sources.get(role, "stated"), []).append(role)
    if roles_of:
        out["angle_repeatability"] = "; ".join(f"{', '.join(roles)}: {source}"
                                               for source, roles in roles_of.items())
    if angle.offset_sigma_deg:
        out["angle_offset"] = "the calibration's angle offsets"
    return out


def calibration_terms(budget: Budget, cal, range_w: np.ndarray, beam_range_w: np.ndarray,
                      optics: ReductionOptics, sources: dict[str, str]) -> list[str]:
    """The type-B components: linearity (own: the detector's relative non-linearity),
    range_gain (shared, a column per range on the sample's and the beam's range,
    `range_columns`: each range's sigma_g / g from the calibration's gains, 0 on its reference
    range, else each range's stated gain error) and solid_angle (shared by all points: the
    calibration's measured aperture, else the aperture's tolerance), or with a reference
    calibration, whose solid angle the reference run measured, its reference_certificate and
    reference_run (shared by all points, calibration.reference); fills `sources` with where
    each comes from and returns notes on what the budget lacks."""
    value = np.abs(budget.bsdf)
    notes = []
    if optics.linearity_rel > 0:
        budget.add_own("linearity", value * optics.linearity_rel)
        sources["linearity"] = optics.sources.get("linearity", "stated")
    else:
        notes.append(_zero_note("linearity", optics,
                                "linearity: not stated ([detector] linearity_rel)"))
    gains = cal.gains if cal is not None else None
    if gains is not None or optics.range_gain_rel > 0:
        gain_rel = ((lambda r: _relative(gains.get(range_key(r)))) if gains is not None
                    else (lambda r: optics.range_gain_rel))
        budget.add_shared("range_gain", value[:, None]
                          * range_columns(range_w, beam_range_w, gain_rel))
        sources["range_gain"] = ("the calibration's range gains" if gains is not None
                                 else optics.sources.get("range_gain", "stated"))
    else:
        notes.append(_zero_note("range_gain", optics, "range_gain: no calibration applied"
                                if cal is None else "range_gain: the calibration has no gains"))
    if cal is not None and cal.reference is not None:
        for name, errors in cal.reference.shared_errors(value).items():
            budget.add_shared(name, errors)
            sources[name] = f"{COMPONENTS[name]} ({cal.reference.source_of(name)})"
    elif measured_aperture(cal):
        budget.add_shared("solid_angle", value * _solid_angle_rel(cal))
        sources["solid_angle"] = "the calibration's measured aperture"
    elif optics.solid_angle_rel > 0:
        budget.add_shared("solid_angle", value * optics.solid_angle_rel)
        sources["solid_angle"] = optics.sources.get("solid_angle", "stated")
    else:
        notes.append(_zero_note("solid_angle", optics, f"solid_angle: the "
                                f"{optics.aperture_from} aperture states no uncertainty"))
    return notes


def reduction_solid_angle_sr(cal, optics: ReductionOptics) -> float:
    """The solid angle reduction divides by: a reference calibration's effective one (checked
    to be of the run's wavelength), else the aperture's."""
    if cal is None or cal.reference is None:
        return optics.aperture_sr
    cal.reference.check_wavelength(optics.wavelength_nm)
    return cal.reference.solid_angle_sr.value


def _zero_note(name: str, optics: ReductionOptics, unstated: str) -> str:
    """The budget's note on a type-B term it lacks: its figure stated as 0 (with where), else
    `unstated`."""
    source = optics.sources.get(name)
    return f"{name}: stated as 0 ({source})" if source is not None else unstated


def measured_aperture(cal) -> bool:
    """Whether a calibration measured the aperture (a scan across the beam, with a sigma); one
    taken from the geometry is the nominal aperture, whose uncertainty is its tolerance."""
    return (cal is not None and cal.aperture_half_angle_deg is not None
            and cal.aperture_method != "geometry" and _solid_angle_rel(cal) > 0)


def _relative(m) -> float:
    """sigma / value of a Measured (0 for None or a zero value)."""
    return float(m.sigma / abs(m.value)) if m is not None and m.value != 0 else 0.0


def _solid_angle_rel(cal) -> float:
    """Relative sigma of the calibration's solid angle: its own, else from the half-angle's
    (dOmega / dbeta = 2 pi sin beta, Omega = 2 pi (1 - cos beta))."""
    if cal.aperture_solid_angle_sr is not None:
        return _relative(cal.aperture_solid_angle_sr)
    beta = math.radians(cal.aperture_half_angle_deg.value)
    return math.sin(beta) * math.radians(cal.aperture_half_angle_deg.sigma) / (1.0 - math.cos(beta))
