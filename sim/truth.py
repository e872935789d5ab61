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
from sim.bench.config import informational, read_table
from sim.bench.sample import Sample
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
        table = read_table(sim_config, "sample", sample)
        alpha = table["alpha"]
        #: The emulated sample: distribution, alpha (one value or (x, y)), eta, masking, and
        #: the single-scattering-equivalent alpha and its uncertainty where [sim.sample]
        #: states them (sim.bench.config.INFORMATIONAL).
        self.sample = {"distribution": table["distribution"],
                       "alpha": alpha[0] if alpha[0] == alpha[1] else list(alpha),
                       "eta": table["eta"], "masking": table["masking"],
                       **informational(table)}

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
        alpha = spec.alpha if spec.alpha[0] != spec.alpha[1] else spec.alpha[0]
        theta = np.linspace(-89.5, 89.5, CURVE_POINTS)
        wi, wo = in_plane_directions(theta_i_deg, theta, transmission)
        theta_i = math.radians(theta_i_deg)
        extras = "".join(f" + {name}" for name, on in (
            ("multiple scattering", sample.multiple_scattering_on(theta_i)),
            ("diffraction", sample.diffraction_on(theta_i, "transmission" if transmission
                                                  else "reflection"))) if on)
        label = f"{spec.distribution} alpha {np.round(alpha, 4)}{extras}"
        curves = {f"{TRUTH} ({label})": (theta, sample.bsdf(wi, wo))}
        half_angle = math.radians(aperture_half_angle_deg)
        if half_angle > 0:
            # a transmitted lobe is about 0.3 alpha rad wide: resolve it across the aperture
            order = order_for(half_angle / (0.3 * float(np.min(alpha))), 1e-3)
            nodes, weights = cap_rule(wo, half_angle, order)
            f = sample.bsdf(np.broadcast_to(wi[:, None, :], nodes.shape), nodes)
            curves[f"{TRUTH} through the aperture"] = (theta, f @ weights / weights.sum())
        return curves


def emulator_shot_noise_w(sim_detector: Mapping | None, wavelength_nm: float) -> float:
    """2 q B / R of the emulated meter a [sim.detector] table describes (EmulatorTruth's
    shot_noise_w, for a table on its own)."""
    meter = PhotodiodeModel(sim_detector)
    return 2.0 * ELEMENTARY_CHARGE_C * meter.bandwidth_hz / meter.responsivity_a_w(wavelength_nm)
