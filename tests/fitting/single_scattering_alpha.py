"""The single-scattering-equivalent alpha of an emulated Walter sample, without a scan.

The emulated samples' [sim.sample] alpha is the microsurface roughness, and the bench adds
multiple scattering on top; a Walter-style fit (single scattering, normal incidence only:
`gonio fit RUN` with its defaults) returns a larger alpha. This computes that alpha from the
bench's exact expectation of the reduced values at the plan's normal-incidence points
(sim.bench.scene.Bench.reduced_bsdf), each weighted by the noise the emulated meter's model
predicts for its reading (read, shot and quantisation noise on the range it autoranges to),
fitted by calibration.fit with the default options: deterministic, noise-free, in seconds
once the bench's tables are walked.
"""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

import numpy as np

from calibration.budget import Budget
from calibration.fit import FitOptions, FitResult, fit
from calibration.reduce import calibration_terms, optics_of
from calibration.reduced import ReducedData
from gonio.config import parse_config
from gonio.plan.parse import load_plan
from gonio.plan.schedule import build_schedule
from model.optics.exit_face import exit_view
from sim.bench import build_bench
from sim.bench.geometry import sample_frame_directions
from sim.devices.photodiode import PhotodiodeModel

ROOT = Path(__file__).resolve().parents[2]
SAMPLES = ("antiglare", "ground-glass", "acid-etched")


def instrument_path(sample: str) -> Path:
    """The example instrument config of one of Walter's samples (SAMPLES)."""
    return ROOT / "examples" / "instruments" / f"sim-walter-{sample}.toml"


def sample_table(sample: str) -> dict:
    """The [sim.sample] table of the sample's instrument config (as written)."""
    return tomllib.loads(instrument_path(sample).read_text())["sim"]["sample"]


def normal_incidence_expectation(sample: str, ms_walks: int | None = None,
                                 seed: int | None = None) -> ReducedData:
    """ReducedData of the example plan's normal-incidence readings on the sample's emulated
    bench: the bench's exact expectation; each point's own sigma the emulated meter's
    predicted noise of its reading (autoranged, the plan's averaging) over the reading's
    scale, and the beam normalisation's error (the mean of the plan's beam readings, each
    with the meter's predicted noise) shared by every point. ms_walks: the
    multiple-scattering tables' walks in place of the config's (None: the config's); seed: the
    [sim] seed the tables are walked from in place of the config's (None: the config's)."""
    path = instrument_path(sample)
    raw = tomllib.loads(path.read_text())
    sim = dict(raw["sim"])
    if ms_walks is not None:
        sim["sample"] = {**sim["sample"], "ms_walks": ms_walks}
    if seed is not None:
        sim["seed"] = seed
    plan = load_plan(ROOT / "examples" / "plans" / f"walter-{sample}.toml")
    readings = build_schedule(plan, parse_config(raw, path)).readings
    rows = readings[(readings["kind"] == "sample") & (readings["theta_i_deg"] == 0.0)]
    beam_rows = readings[readings["kind"] == "beam"]
    bench = build_bench(sim, raw["optics"], plan.raw["sample"])
    bsdf = bench.reduced_bsdf(rows["sample_deg"], rows["arm_deg"])
    wi, wo = sample_frame_directions({"sample": rows["sample_deg"], "arm": rows["arm_deg"]},
                                     flipped=bench.sample.flipped)
    w_eval, factor = exit_view(bench.sample.spec, wi, wo)
    scale = bench.source.power_w * bench.integral.solid_angle_sr * factor * np.abs(wo[:, 2])
    meter = PhotodiodeModel(sim.get("detector"), seed=0)
    wavelength = bench.source.wavelength_nm
    averaging = int(plan.averaging or raw["detector"].get("averaging", 1))

    def noise_w(power_w: float) -> float:
        return meter.expected_sigma_w(power_w, meter.autorange(power_w, wavelength), averaging,
                                      wavelength)

    beam_w = bench.source.power_w * bench.direct_beam_fraction(float(beam_rows["arm_deg"][0]))
    beam_rel = noise_w(beam_w) / beam_w / math.sqrt(len(beam_rows))
    budget = Budget(bsdf)
    budget.add_own("noise", np.array([noise_w(p) for p in bsdf * scale]) / scale)
    budget.add_shared("beam_normalisation", beam_rel * bsdf)
    # the type-B terms reduction adds by default, as it adds them (calibration.reduce)
    range_w = np.array([meter.autorange(p, wavelength) for p in bsdf * scale])
    calibration_terms(budget, None, range_w, np.full(len(bsdf), meter.autorange(beam_w,
                                                                                wavelength)),
                      optics_of(raw, None, plan.raw), {})
    meta = {"eta": bench.sample.spec.eta,
            "aperture_half_angle_deg": math.degrees(bench.integral.aperture_rad),
            "beam_divergence_deg": math.degrees(bench.integral.divergence_rad)}
    return ReducedData(wi, w_eval, bsdf, budget.sigma, np.ones(len(bsdf), bool),
                       (wo[:, 2] > 0) != (wi[:, 2] > 0), meta, budget.shared_rel,
                       components=budget.components)


def single_scattering_fit(sample: str, ms_walks: int | None = None,
                          distributions: tuple[str, ...] | None = None,
                          seed: int | None = None) -> FitResult:
    """The default fit (`gonio fit RUN`: separable masking, normal incidence, every
    distribution unless `distributions` names some) of normal_incidence_expectation."""
    options = FitOptions() if distributions is None else FitOptions(distributions=distributions)
    return fit(normal_incidence_expectation(sample, ms_walks, seed), options)

