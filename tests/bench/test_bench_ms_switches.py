"""The [sim.sample] multiple_scattering and diffraction switches: "auto" computes an effect only
where it can reach the detector above its noise floor, true / false override, bad values fail."""

from __future__ import annotations

import math

import numpy as np
import pytest

from model.bsdf.diffraction import needs_diffraction
from model.bsdf.multiple_scattering import energy_loss
from model.optics.exit_face import exit_view
from sim.bench import build_bench
from sim.bench.sample import Sample, SampleSpec
from sim.devices.photodiode import SimConfigError

AUTO = {"multiple_scattering": "auto", "diffraction": "auto"}
WALTER = {  # the paper's three samples, with nano-roughness far above the wavelength (also in
    # transmission, whose phase path n cos theta_t - cos theta_i is ~4x shorter than 2 cos theta)
    "antiglare": {**AUTO, "distribution": "beckmann", "alpha": 0.023, "rms_height_nm": 2000.0,
                  "correlation_length_um": 31.0},
    "ground": {**AUTO, "distribution": "ggx", "alpha": 0.394, "rms_height_nm": 1500.0,
               "correlation_length_um": 5.4},
    "etched": {**AUTO, "distribution": "ggx", "alpha": 0.553, "rms_height_nm": 1200.0,
               "correlation_length_um": 3.1},
}
#: a polished-then-lapped metal: rms roughness a tenth of the wavelength
FINE_METAL = {**AUTO, "kind": "conductor", "distribution": "ggx", "alpha": 0.1, "eta": 0.2,
              "k": 3.4, "rms_height_nm": 40.0, "correlation_length_um": 2.0}


def readings(bench, incidences=(0.0, 30.0, 60.0), offsets=(0.0, 5.0, 40.0)) -> np.ndarray:
    """Scattered fractions at and beside the mirror direction and the straight beam."""
    out = []
    for s in incidences:
        for arm in (2 * s, 180.0):  # arm = 2 s: the mirror direction; 180: straight through
            for d in offsets:
                out.append(bench.scattered_fraction({"sample": s, "arm": arm + d}))
    return np.array(out)


def test_auto_computes_neither_effect_for_the_antiglare_glass():
    bench = build_bench({"sample": WALTER["antiglare"]})
    values = readings(bench)
    sample = bench.sample
    assert np.all(values >= 0) and values.max() > 1e-3
    assert sample.evaluations["reflection"] > 0 and sample.evaluations["transmission"] > 0
    assert sample.evaluations["random_walk"] == 0 and sample.evaluations["diffraction"] == 0
    assert not any(isinstance(key[0], str) and key[0] in ("random_walk", "diffraction")
                   for key in sample._models), "no walk or diffraction model is even built"
    assert energy_loss("beckmann", 0.023, 1.51, math.radians(60), "correlated") \
        < sample.visible_fraction


@pytest.mark.parametrize("name", sorted(WALTER))
def test_auto_computes_no_diffraction_for_the_walter_samples(name):
    sample = build_bench({"sample": WALTER[name]}).sample
    lam = sample.wavelength_m
    sigma = WALTER[name]["rms_height_nm"] * 1e-9
    for theta in np.radians([0.0, 30.0, 60.0]):  # the paper's incidences
        assert not sample.diffraction_on(theta)
        # geometric optics: the specular (Harvey-Shack) share is below the noise floor
        a = math.exp(-(4 * math.pi * sigma * math.cos(theta) / lam) ** 2)
        assert a < sample.visible_fraction
    # at grazing incidence every surface turns smooth (Rayleigh's criterion) and diffracts
    assert sample.diffraction_on(math.radians(89.0))


def test_auto_switches_multiple_scattering_on_for_rough_ggx_at_grazing_incidence():
    bench = build_bench({"sample": {**AUTO, "distribution": "ggx", "alpha": 1.0,
                                    "masking": "correlated"}})
    sample = bench.sample
    assert sample.multiple_scattering_on(math.radians(80.0))
    positions = {"sample": 80.0, "arm": 30.0}  # reflected, far from the mirror direction
    with_ms = bench.scattered_fraction(positions)
    assert sample.evaluations["random_walk"] > 0
    off = build_bench({"sample": {"distribution": "ggx", "alpha": 1.0, "masking": "correlated",
                                  "multiple_scattering": False}})
    without = off.scattered_fraction(positions)
    assert off.sample.evaluations["random_walk"] == 0
    assert with_ms > 1.2 * without  # a broad lobe single scattering misses


def test_added_energy_is_what_single_scattering_loses():
    """Integral over the sphere of (with - without) f |cos o|: the energy of orders >= 2, which
    for glass is exactly energy_loss (R + T = 1 for the walk)."""
    theta = math.radians(80.0)
    spec = SampleSpec(distribution="ggx", alpha=(1.0, 1.0), masking="correlated",
                      ms_walks=4096, multiple_scattering="auto")
    on, off = Sample(spec, seed=3), Sample(SampleSpec(**{**spec.__dict__,
                                                         "multiple_scattering": False}))
    rng = np.random.default_rng(11)
    n = 3000
    u = rng.random((n, 3))  # cosine-weighted about +z and -z
    r, phi = np.sqrt(u[:, 0]), 2 * np.pi * u[:, 1]
    z = np.sqrt(1 - u[:, 0]) * np.where(u[:, 2] < 0.5, 1.0, -1.0)
    wo = np.stack([r * np.cos(phi), r * np.sin(phi), z], -1)
    wi = np.broadcast_to([math.sin(theta), 0.0, math.cos(theta)], wo.shape)
    _, factor = exit_view(spec, wi, wo)
    extra = (on.integrand(wi, wo) - off.integrand(wi, wo)) / factor
    terms = extra / (0.5 * np.abs(z) / np.pi)
    added, stderr = terms.mean(), terms.std(ddof=1) / math.sqrt(n)
    loss = energy_loss("ggx", 1.0, 1.51, theta, "correlated")
    assert loss > 0.5
    assert abs(added - loss) < 4 * stderr + 0.01, (added, stderr, loss)
    assert stderr < 0.03


def test_auto_diffraction_for_roughness_comparable_to_the_wavelength():
    bench = build_bench({"sample": FINE_METAL})
    sample = bench.sample
    lam = sample.wavelength_m
    for theta in np.radians([0.0, 45.0, 80.0]):
        assert sample.diffraction_on(theta)
        assert needs_diffraction(40e-9, lam, theta, threshold=sample.visible_fraction)
    plain = build_bench({"sample": {**FINE_METAL, "diffraction": False}})
    peak = {"sample": 20.0, "arm": 40.0}  # the mirror direction
    aside = {"sample": 20.0, "arm": 70.0}
    assert bench.scattered_fraction(peak) < 0.9 * plain.scattered_fraction(peak)
    assert bench.scattered_fraction(aside) > 1.1 * plain.scattered_fraction(aside)
    assert sample.evaluations["diffraction"] > 0 and plain.sample.evaluations["diffraction"] == 0
    # a polished surface (rms 0.05 nm) diffracts too little to see: not computed
    polished = build_bench({"sample": {**FINE_METAL, "rms_height_nm": 0.05}}).sample
    assert not polished.diffraction_on(0.0)


def test_explicit_switches_override_auto():
    forced = build_bench({"sample": {**WALTER["antiglare"], "multiple_scattering": True,
                                     "diffraction": True}})
    forced.scattered_fraction({"sample": 30.0, "arm": 75.0})
    assert forced.sample.evaluations["random_walk"] > 0
    assert forced.sample.evaluations["diffraction"] > 0
    never = build_bench({"sample": {**FINE_METAL, "alpha": 1.0, "multiple_scattering": False,
                                    "diffraction": False}})
    never.scattered_fraction({"sample": 80.0, "arm": 30.0})
    assert never.sample.evaluations["random_walk"] == 0
    assert never.sample.evaluations["diffraction"] == 0


def test_defaults_are_auto():
    spec = build_bench({}).sample.spec
    assert spec.multiple_scattering == "auto" and spec.diffraction == "auto"


@pytest.mark.parametrize("name,on_at", [("antiglare", ()), ("ground", (0, 30, 60, 75)),
                                        ("etched", (0, 30, 60, 75))])
def test_auto_multiple_scattering_for_the_walter_samples(name, on_at):
    """The rule: on at an incidence where the energy single scattering loses (energy_loss,
    height-correlated masking) exceeds visible_fraction, the detector's noise floor as a share
    of the beam; Walter's ground and etched glass lose 2-4 % at normal incidence (on at every
    incidence), the anti-glare glass < 1e-5 up to 60 deg (off)."""
    table = {k: v for k, v in WALTER[name].items() if k not in ("multiple_scattering",)}
    sample = build_bench({"sample": table}).sample
    for theta in (0, 30, 60, 75):
        loss = energy_loss(table["distribution"], table["alpha"], 1.51, math.radians(theta),
                           "correlated")
        assert sample.multiple_scattering_on(math.radians(theta)) == (theta in on_at)
        assert (loss > sample.visible_fraction) == (theta in on_at)


def test_auto_follows_the_detector_noise_floor():
    """A noisier detector (5000x the read noise) no longer sees ground glass's multiple
    scattering at normal incidence (energy lost 0.020 < its visible_fraction), but still at
    75 deg (0.16 lost)."""
    quiet = build_bench({"sample": WALTER["ground"]}).sample
    noisy = build_bench({"sample": WALTER["ground"],
                         "detector": {"read_noise_fraction": 0.5}}).sample
    assert noisy.visible_fraction > 100 * quiet.visible_fraction
    assert quiet.multiple_scattering_on(0.0) and not noisy.multiple_scattering_on(0.0)
    assert noisy.multiple_scattering_on(math.radians(75.0))


@pytest.mark.parametrize("table,key", [
    ({"multiple_scattering": "yes"}, "multiple_scattering"),
    ({"multiple_scattering": 1}, "multiple_scattering"),
    ({"diffraction": "on"}, "diffraction"),
    ({"diffraction": True}, "rms_height_nm"),
    ({"rms_height_nm": 20.0}, "correlation_length_um"),
    ({"rms_height_nm": -1.0, "correlation_length_um": 1.0}, "rms_height_nm"),
    ({"ms_walks": 0}, "ms_walks"),
    ({"ms_walks": (1 << 25) + 1}, "ms_walks"),
    ({"distribution": "phong", "multiple_scattering": True}, "multiple_scattering"),
])
def test_bad_switch_values_name_the_key(table, key):
    with pytest.raises(SimConfigError, match=rf"\[sim.sample\] {key}") as err:
        build_bench({"sample": table})
    assert len(str(err.value).splitlines()) == 1
