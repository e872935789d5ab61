"""The emulator's truth of an all-emulated run: the sample the emulated bench measured, its
meter's shot noise and the bench's own BSDF curves. Reduction, plots and the live view show it
beside the data; the composition roots hand it to calibration (calibration.emulator_truth)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from functools import cached_property

import numpy as np

from model.optics.aperture import order_for
from model.optics.directions import in_plane_directions
from model.optics.quadrature import cap_rule
from sim.bench import build_bench
from sim.bench.config import read_sample
from sim.bench.sample import MICROFACET, Sample, SampleSpec
from sim.devices.photodiode import ELEMENTARY_CHARGE_C, PhotodiodeModel

#: The legend label of the emulated bench's own BSDF (never "model": it is no fit).
TRUTH = "emulator truth"
#: Points of a truth curve across the plane of incidence.
CURVE_POINTS = 721


class EmulatorTruth:
    """What the emulator pretended, for a run's [sim] table on the [optics] and plan [sample]
    tables the experimenter described (as the scan built its bench). Bad [sim] fields raise
    sim.devices.photodiode.SimConfigError (a ValueError) naming the field."""

    def __init__(self, sim_config: Mapping, optics: Mapping | None = None,
                 sample: Mapping | None = None) -> None:
        self.sim_config, self.optics, self.described_sample = sim_config, optics, sample
        _, spec, _, stated = read_sample(sim_config, sample)
        #: The emulated sample: distribution, alpha (one value or (x, y)), eta, masking, and
        #: the single-scattering-equivalent alpha and its uncertainty where [sim.sample]
        #: states them (sim.bench.config.INFORMATIONAL); for a model family's sample, its
        #: `family` and its parameters and settings by name.
        self.sample = truth_of_spec(spec) if spec.family != MICROFACET else {
            "distribution": spec.distribution, "alpha": _alpha(spec), "eta": spec.eta,
            "masking": spec.masking, **stated}

    def shot_noise_w(self, wavelength_nm: float) -> float:
        """Shot-noise variance of one sample of the emulated meter per watt of signal, W^2/W:
        2 q B / R ([sim.detector] bandwidth B, responsivity R at the wavelength). The dark
        readings' scatter holds only the read noise and the dark current's shot noise; a
        signal of 1e-9 W or more on the 1e-8 W range has shot noise above that (up to 2.5
        times its sigma at full scale)."""
        return emulator_shot_noise_w(self.sim_config.get("detector"), wavelength_nm)

    @cached_property
    def bench_sample(self) -> Sample:
        """The bench's Sample (built once: its multiple-scattering tables are walked here)."""
        return build_bench(self.sim_config, self.optics, self.described_sample).sample

    def curves(self, theta_i_deg: float, transmission: bool,
               aperture_half_angle_deg: float = 0.0) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """{label: (signed theta_o deg, BSDF)} of the bench's own BSDF in the plane of
        incidence, with the multiple scattering and diffraction its "auto" switches turn on:
        point values, and averaged over the aperture when its half-angle is given."""
        sample = self.bench_sample
        spec = sample.spec
        theta = np.linspace(-89.5, 89.5, CURVE_POINTS)
        wi, wo = in_plane_directions(theta_i_deg, theta, transmission)
        theta_i = math.radians(theta_i_deg)
        extras = "".join(f" + {name}" for name, on in (
            ("multiple scattering", sample.multiple_scattering_on(theta_i)),
            ("diffraction", sample.diffraction_on(theta_i, "transmission" if transmission
                                                  else "reflection"))) if on)
        label = (f"{spec.distribution} alpha {np.round(_alpha(spec), 4)}{extras}"
                 if spec.family == MICROFACET else family_label(spec))
        curves = {f"{TRUTH} ({label})": (theta, sample.bsdf(wi, wo))}
        half_angle = math.radians(aperture_half_angle_deg)
        if half_angle > 0:
            # a transmitted lobe is about 0.3 alpha rad wide, a family's lobe as wide as it
            # is at its mirror direction: resolve it across the aperture
            order = order_for(half_angle / _lobe_width(sample, wi[0]), 1e-3)
            nodes, weights = cap_rule(wo, half_angle, order)
            f = sample.bsdf(np.broadcast_to(wi[:, None, :], nodes.shape), nodes)
            curves[f"{TRUTH} through the aperture"] = (theta, f @ weights / weights.sum())
        return curves


def _lobe_width(sample: Sample, wi: np.ndarray) -> float:
    """The narrowest width (rad) of the sample's lobes at incidence wi: 0.3 alpha for the
    microfacet interface, a family's own width at the mirror direction."""
    if sample.spec.family == MICROFACET:
        return 0.3 * min(sample.spec.alpha)
    return sample.lobe_scales(wi, wi * np.array([-1.0, -1.0, 1.0])).width_o


def _alpha(spec: SampleSpec) -> float | list[float]:
    """The microsurface's alpha: one value, or [alpha_x, alpha_y]."""
    return spec.alpha[0] if spec.alpha[0] == spec.alpha[1] else list(spec.alpha)


def truth_of_spec(spec: SampleSpec) -> dict[str, object]:
    """A model family's sample as the truth states it: `family`, then its parameters and fixed
    settings by the names a fit reports."""
    return {"family": spec.family, **dict(spec.family_parameters),
            **dict(spec.family_settings)}


def family_label(spec: SampleSpec) -> str:
    """A family sample's truth in a legend: `lambert+microfacet rho 0.35, alpha 0.12, eta 1.5,
    ggx`."""
    values = ", ".join(f"{name} {value:.4g}" for name, value in spec.family_parameters)
    settings = "".join(f", {value}" for _, value in spec.family_settings)
    return f"{spec.family} {values}{settings}"


def emulator_shot_noise_w(sim_detector: Mapping | None, wavelength_nm: float) -> float:
    """2 q B / R of the emulated meter a [sim.detector] table describes (EmulatorTruth's
    shot_noise_w, for a table on its own)."""
    meter = PhotodiodeModel(sim_detector)
    return 2.0 * ELEMENTARY_CHARGE_C * meter.bandwidth_hz / meter.responsivity_a_w(wavelength_nm)
