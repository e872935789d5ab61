"""Raw readings of an in-plane scan drawn with every error the GUM budget names, each from its
own physical process (not from the budget's formulas): the stages stand off their reported
positions by a calibration residual common to the run plus each move's scatter, the beam drifts,
each range has a gain error and a dark level, the detector has read and shot noise and a
non-linearity, the aperture's solid angle differs from the calibration's. The truth is the
model at the reported positions, what the reduced values estimate."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np

from calibration.aperture import solid_angle_sr
from calibration.calfile import Calibration
from calibration.detector import range_key
from calibration.fit import build_model
from calibration.reduce import ReductionOptics
from calibration.smearing import aperture_average
from calibration.values import Measured
from gonio.geometry import directions, sample_angles, stage_angles
from gonio.sample import SampleInfo
from gonio.store import READING_DTYPE
from sim.bench.sample import SampleSpec, exit_view

RANGES_W = (1e-8, 1e-7, 1e-6, 1e-5, 1e-4, 1e-3, 1e-2)


@dataclass(frozen=True)
class Scan:
    """The bench and its errors (1-sigma unless said), degrees, W, relative."""

    distribution: str = "beckmann"
    alpha: float = 0.05
    eta: float = 1.51
    theta_i_deg: float = 30.0
    half_angle_deg: float = 0.2
    half_angle_sigma_deg: float = 2e-4
    beam_w: float = 5e-3
    drift: float = 5e-3  # relative amplitude of a slow sinusoidal drift
    read_noise_fs: float = 2e-5  # read noise per full scale
    dark_fs: float = 1e-3  # dark level per full scale
    shot_per_w: float = 2e-15  # shot-noise variance per watt of signal, W
    gain_sigma: float = 1e-3  # every range but the reference (1e-2 W)
    linearity: float = 5e-4  # half-width of a uniform relative deviation per reading
    offset_sigma_deg: tuple[float, float] = (3e-3, 3e-3)  # sample, arm: the calibration's
    repeatability_deg: tuple[float, float] = (5e-3, 5e-3)  # sample, arm: each move's
    darks_per_range: int = 30
    beam_every: int = 8
    reference_gain_error: bool = False  # the beam's range has a gain error too (no calibration)
    rectangular: bool = False  # gains, stage scatter, aperture: uniform laws of the same sigma

    def calibration(self) -> Calibration:
        """What the calibration says: offsets and gains 0 and 1 with their sigmas."""
        gains = {range_key(r): Measured(1.0, 0.0 if r == RANGES_W[-1] else self.gain_sigma)
                 for r in RANGES_W}
        return Calibration(
            created_utc="synthetic", gains=gains, gain_reference=range_key(RANGES_W[-1]),
            dark_offsets_w={range_key(r): Measured(0.0, 0.0) for r in RANGES_W},
            sample_offset_deg=Measured(0.0, self.offset_sigma_deg[0]),
            arm_offset_deg=Measured(0.0, self.offset_sigma_deg[1]),
            aperture_half_angle_deg=Measured(self.half_angle_deg, self.half_angle_sigma_deg))

    def optics(self) -> ReductionOptics:
        """What reduction takes: the sample, the calibration's aperture, the shot noise and the
        non-linearity as the config would state them (the uniform law's sigma)."""
        sample = SampleInfo(id="synthetic", kind="hemisphere", eta=self.eta)
        return ReductionOptics(sample, self.half_angle_deg, "calibration", 633.0,
                               shot_variance_per_w=self.shot_per_w,
                               linearity_rel=self.linearity / math.sqrt(3.0))

    def model(self):
        """The sample's BSDF."""
        return build_model(self.distribution, self.alpha, self.eta, "separable")

    def planned(self) -> tuple[np.ndarray, np.ndarray]:
        """(theta_o, transmission) of the scan: across the reflected and the refracted lobe,
        its flanks densest."""
        refracted = math.degrees(math.asin(math.sin(math.radians(self.theta_i_deg)) / self.eta))
        width = math.degrees(self.alpha) * 3.0
        blocks = [(np.linspace(self.theta_i_deg - width, self.theta_i_deg + width, 41), False),
                  (np.linspace(refracted - width / 2, refracted + width / 2, 41), True)]
        return (np.concatenate([b[0] for b in blocks]),
                np.concatenate([np.full(len(b[0]), b[1]) for b in blocks]))

    def reading_model(self, sample_deg, arm_deg, half_angle_deg: float) -> np.ndarray:
        """Detector power per beam watt per sr of aperture: f averaged over the aperture times
        the exit factor and |cos o|, with the stages at the given positions."""
        wi, wo = directions(sample_deg, arm_deg)
        w_eval, factor = exit_view(SampleSpec(kind="hemisphere", eta=self.eta), wi, wo)
        f = aperture_average(self.model(), wi, w_eval, half_angle_deg, 12)
        return f * factor * np.abs(wo[:, 2]), factor * np.abs(wo[:, 2])

    def error(self, rng: np.random.Generator, sigma, size=None) -> np.ndarray:
        """Errors of standard deviation `sigma`: normal, or uniform +-sigma sqrt(3) when
        `rectangular` (a datasheet's +-a read as GUM's rectangular law)."""
        if self.rectangular:
            half = np.sqrt(3.0) * np.asarray(sigma, dtype=np.float64)
            return rng.uniform(-half, half, size if size is not None else np.shape(half))
        return rng.normal(0.0, sigma, size)

    def draw(self, seed: int) -> tuple[np.ndarray, np.ndarray]:
        """(readings in READING_DTYPE, truth: the BSDF at each sample reading's reported
        position). In time order: the dark readings, then blocks of beam_every sample
        readings, each after a beam reading (the sample stage turns to the beam position and
        back: a new move, so one scatter per block; the arm moves for every reading)."""
        rng = np.random.default_rng(seed)
        theta_o, transmission = self.planned()
        st = stage_angles(self.theta_i_deg, theta_o, 0.0, transmission)
        n = len(theta_o)
        block = np.arange(n) // self.beam_every
        offsets = rng.normal(0.0, self.offset_sigma_deg)
        sample_true = (st.sample_deg + offsets[0]
                       + self.error(rng, self.repeatability_deg[0], block[-1] + 1)[block])
        arm_true = st.arm_deg + offsets[1] + self.error(rng, self.repeatability_deg[1], n)
        half_true = self.half_angle_deg + self.error(rng, self.half_angle_sigma_deg)
        omega_true = solid_angle_sr(math.radians(half_true))
        power_per_w, _ = self.reading_model(sample_true, arm_true, self.half_angle_deg)
        nominal, cos_factor = self.reading_model(st.sample_deg, st.arm_deg, self.half_angle_deg)
        truth = nominal / cos_factor

        t_sample = np.arange(n) + block + 2.0  # a beam reading before each block
        t_beam = np.arange(block[-1] + 2) * (self.beam_every + 1) + 1.0
        source = lambda t: self.beam_w * (1.0 + self.drift * np.sin(2 * np.pi * t / 400.0 + 1.0))  # noqa: E731
        gain_err = {r: (0.0 if r == RANGES_W[-1] and not self.reference_gain_error
                        else self.error(rng, self.gain_sigma)) for r in RANGES_W}
        dark = {r: self.dark_fs * r for r in RANGES_W}

        net = source(t_sample) * omega_true * power_per_w
        net *= 1.0 + rng.uniform(-self.linearity, self.linearity, n)
        fs = np.array([min(r for r in RANGES_W if r >= 1.05 * p) for p in net])
        measured = net * (1.0 + np.array([gain_err[r] for r in fs]))
        measured += rng.normal(0.0, np.sqrt(self.shot_per_w * net))
        measured += np.array([dark[r] for r in fs])
        measured += rng.normal(0.0, self.read_noise_fs * fs)

        beam_fs = RANGES_W[-1]
        beam = (source(t_beam) * (1.0 + gain_err[beam_fs]) + dark[beam_fs]
                + rng.normal(0.0, self.read_noise_fs * beam_fs, len(t_beam)))
        used = sorted(set(fs.tolist()) | {beam_fs})
        dark_range = np.repeat(used, self.darks_per_range)
        dark_power = (np.array([dark[r] for r in dark_range])
                      + rng.normal(0.0, self.read_noise_fs * dark_range))

        out = np.zeros(n + len(t_beam) + len(dark_range), dtype=READING_DTYPE)
        out["kind"] = ["sample"] * n + ["beam"] * len(t_beam) + ["dark"] * len(dark_range)
        out["side"] = [("transmission" if t else "reflection") for t in transmission] + \
            [""] * (len(t_beam) + len(dark_range))
        out["flags"] = ""
        out["power_w"] = np.concatenate([measured, beam, dark_power])
        out["range_w"] = np.concatenate([fs, np.full(len(t_beam), beam_fs), dark_range])
        out["t_s"] = np.concatenate([t_sample, t_beam, np.full(len(dark_range), 0.0)])
        out["index"] = np.argsort(np.argsort(out["t_s"], kind="stable"), kind="stable")
        out["sample_deg"], out["arm_deg"] = 90.0, 180.0  # beam and dark: sample retracted
        out["sample_deg"][:n], out["arm_deg"][:n] = st.sample_deg, st.arm_deg
        a = sample_angles(st.sample_deg, st.arm_deg)
        for name in a._fields:
            out[name][:n] = getattr(a, name)
        return out, truth


#: The bench of the coverage at the declared specifications: an ESP301 driving both stages, a
#: PM100 reading the detector, a 3.5 mm aperture at 500 mm (its tolerance class gives the
#: solid angle's uncertainty when no calibration measures it).
APERTURE_MM = (3.5, 500.0)


def spec_config(scan: Scan) -> dict:
    """The stored config of a bench of the declared kinds (gonio.device_kinds.specs), stating
    none of the type-B figures itself, and the shot noise the scan draws."""
    return {"devices": {"esp": {"protocol": "esp"}, "pm100": {"protocol": "pm100"}},
            "axes": {"sample": {"device": "esp", "axis": 1}, "arm": {"device": "esp", "axis": 2}},
            "detector": {"device": "pm100", "shot_noise_w": scan.shot_per_w},
            "optics": {"wavelength_nm": 633.0, "bandwidth_nm": 0.0, "beam_diameter_mm": 1.0,
                       "divergence_deg": 0.0, "aperture_diameter_mm": APERTURE_MM[0],
                       "aperture_distance_mm": APERTURE_MM[1]}}


def spec_scan(theta_i_deg: float, calibrated: bool, rectangular: bool = False) -> Scan:
    """A scan whose every type-B error is drawn at the declared specifications: the PM100's
    non-linearity and (uncalibrated) range gains, every range's, the beam's included; the
    ESP stages' repeatability; (uncalibrated) the aperture diameter's ISO 2768-f tolerance,
    else the calibration's gains, aperture and stage zeros, as Scan draws them."""
    from calibration.type_b import solid_angle_figure
    from gonio.device_kinds.specs import ESP, PM100
    from gonio.optics import optics_of_config

    optics = optics_of_config(spec_config(Scan()))
    half = optics.aperture_half_angle_deg
    stage = ESP.repeatability_deg.sigma
    changes = {"theta_i_deg": theta_i_deg, "half_angle_deg": half, "rectangular": rectangular,
               "linearity": PM100.linearity_rel.sigma * math.sqrt(3.0),
               "repeatability_deg": (stage, stage)}
    if not calibrated:
        # the half-angle's sigma that gives the solid angle's (dOmega / Omega per dbeta)
        omega_per_deg = (math.sin(math.radians(half)) * math.radians(1.0)
                         / (1.0 - math.cos(math.radians(half))))
        changes.update(gain_sigma=PM100.range_gain_rel.sigma, reference_gain_error=True,
                       offset_sigma_deg=(0.0, 0.0),
                       half_angle_sigma_deg=solid_angle_figure(optics).sigma / omega_per_deg)
    return dataclasses.replace(Scan(), **changes)


def spec_run(scan: Scan) -> SimpleNamespace:
    """What reduce_readings reads from a run of the declared bench (spec_config) and a plan
    whose [sample] is the scan's."""
    sample = {"id": "synthetic", "kind": "hemisphere", "eta": scan.eta}
    return SimpleNamespace(config=spec_config(scan), plan={"sample": sample}, path="synthetic",
                           meta={})


def run_of(scan: Scan) -> SimpleNamespace:
    """What reduce_readings reads from a run: its config's axes (the repeatability) and path."""
    axes = {"sample": {"repeatability_deg": scan.repeatability_deg[0]},
            "arm": {"repeatability_deg": scan.repeatability_deg[1]}}
    return SimpleNamespace(config={"axes": axes}, plan={}, path="synthetic", meta={})
