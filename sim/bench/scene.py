"""The bench as a whole: stage positions (+ alignment errors) -> true optical power at the detector.

With the sample in the beam the detector sees the sample's scattering (the aperture integral,
only the lobe on the detector's side evaluated); with the sample retracted (edge-on) it sees the
direct beam, clipped by the aperture when the beam is wider or the arm is off the beam axis.
Either way the instrument's own scatter (sim.bench.stray: a halo about the beam, stray light
from the arm) adds to it.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field, replace

import numpy as np

from model.optics.aperture import ApertureIntegral, LobeScales
from model.optics.exit_face import exit_view
from sim.bench import tables
from sim.bench.geometry import angle_from_beam_rad, sample_frame_directions
from sim.bench.sample import Sample
from sim.bench.source import Source
from sim.bench.stray import InstrumentScatter

ONE_POINT = LobeScales(1.0, 1.0, 1.0, 1.0)  # scales for a probe whose order is fixed anyway
NEGLIGIBLE = 1e-14  # fraction of the incident power below which a tail is not refined
#: where warm_up reads when it does not know where the stages stand: sample 20 deg, the arm on
#: the transmitted side (its mirror, arm 320 deg, on the reflected)
WARM_UP_PLACE = {"sample": 20.0, "arm": 140.0}


@dataclass(frozen=True)
class Alignment:
    """Known mechanical errors: the true angle is the stage's reported angle plus the offset,
    plus, with a repeatability, a scatter drawn anew (N(0, repeatability), from `seed`) each
    time the stage's reported angle changes: where a move ends, which the encoder cannot see."""

    sample_offset_deg: float = 0.0
    arm_offset_deg: float = 0.0
    sample_repeatability_deg: float = 0.0
    arm_repeatability_deg: float = 0.0
    seed: int = 0
    _moves: dict = field(default_factory=dict, compare=False, repr=False)

    def true_positions(self, positions: Mapping[str, float]) -> dict[str, float]:
        """Stage positions corrected to the sample's and arm's true angles."""
        true = {"azimuth": 0.0, "elevation": 0.0, **positions}
        true["sample"] = (positions["sample"] + self.sample_offset_deg
                          + self._scatter("sample", positions["sample"],
                                          self.sample_repeatability_deg))
        true["arm"] = (positions["arm"] + self.arm_offset_deg
                       + self._scatter("arm", positions["arm"], self.arm_repeatability_deg))
        return true

    def placed(self, positions: Mapping[str, float]) -> dict[str, float]:
        """Stage positions with the offsets alone (no move's scatter drawn): where a reading
        at reported `positions` is expected to look."""
        return {"azimuth": 0.0, "elevation": 0.0, **positions,
                "sample": positions["sample"] + self.sample_offset_deg,
                "arm": positions["arm"] + self.arm_offset_deg}

    def _scatter(self, role: str, reported: float, sigma: float) -> float:
        """This move's scatter of a stage: kept while its reported angle stays put."""
        if sigma == 0.0:
            return 0.0
        last = self._moves.get(role)
        if last is None or last[0] != reported:
            rng = self._moves.setdefault("rng", np.random.default_rng(self.seed))
            last = self._moves[role] = (reported, float(rng.normal(0.0, sigma)))
        return last[1]


def disk_overlap_fraction(r_beam: float, r_aperture: float, offset: float) -> float:
    """Fraction of a uniform disk of radius r_beam inside a disk of radius r_aperture whose
    centre is offset away (the lens-shaped intersection area over the beam's area)."""
    r1, r2, d = r_beam, r_aperture, abs(offset)
    if d >= r1 + r2:
        return 0.0
    if d <= abs(r2 - r1):
        return min(1.0, (r2 / r1) ** 2)
    a1 = r1**2 * math.acos((d**2 + r1**2 - r2**2) / (2 * d * r1))
    a2 = r2**2 * math.acos((d**2 + r2**2 - r1**2) / (2 * d * r2))
    kite = 0.5 * math.sqrt((-d + r1 + r2) * (d + r1 - r2) * (d - r1 + r2) * (d + r1 + r2))
    return (a1 + a2 - kite) / (math.pi * r1**2)


@dataclass
class Bench:
    """Source, sample, aperture (diameter and distance), alignment and the instrument's own
    scatter: `power_w(positions, t)`."""

    source: Source
    sample: Sample
    aperture_diameter_mm: float = 10.0
    distance_mm: float = 500.0
    rtol: float = 1e-3
    alignment: Alignment = field(default_factory=Alignment)
    retracted_beyond_deg: float = 89.0
    order: tuple[int, int] | None = None
    stray: InstrumentScatter = field(default_factory=InstrumentScatter)

    def __post_init__(self) -> None:
        self.integral = ApertureIntegral(
            math.atan(0.5 * self.aperture_diameter_mm / self.distance_mm),
            self.source.divergence_rad, self.rtol, self.order)
        self.probe = replace(self.integral, order=(0, 2))

    def retracted(self, sample_deg: float) -> bool:
        """True when the sample is edge-on enough to be out of the beam."""
        return abs(math.sin(math.radians(sample_deg))) >= math.sin(
            math.radians(self.retracted_beyond_deg))

    def direct_beam_fraction(self, arm_deg: float, elevation_deg: float = 0.0) -> float:
        """Fraction of the unobstructed beam's power that enters the aperture."""
        off_axis = float(angle_from_beam_rad(arm_deg, elevation_deg))
        if off_axis >= math.pi / 2:
            return 0.0
        r_beam = 0.5 * self.source.diameter_at_mm(self.distance_mm)
        return disk_overlap_fraction(r_beam, 0.5 * self.aperture_diameter_mm,
                                     self.distance_mm * math.tan(off_axis))

    def scattered_fraction(self, positions: Mapping[str, float]) -> float:
        """Detector power over incident power with the sample in the beam (true positions).

        Far from the lobe's peak, a low-order probe that finds less than NEGLIGIBLE of the
        incident power is returned as is: the order rule would spend thousands of evaluations
        on a tail no detector can see. The probe's cap is split along any edge of the lobe
        inside it, so a sliver of the lobe past an edge gets nodes of its own; with an edge
        inside the beam cone (which the probe's one incident direction cannot see) the full
        rule is used."""
        wi, wo = sample_frame_directions(positions, flipped=self.sample.flipped)
        if self.order is None and self._far_from_peak(wi, wo):
            edges = self.sample.edge_circles(wi)
            edge_in_beam = edges is not None and edges.distance(
                wo, wi, free_is_wo=False) < self.integral.divergence_rad
            if not edge_in_beam:
                model_edges = None if edges is None else replace(edges, table_step_deg=None)
                split = ONE_POINT._replace(edge_o=0.0, edges=model_edges)
                probe = self.probe.integrate(self.sample.integrand, wi, wo, split)
                if probe < NEGLIGIBLE:
                    return probe
        scales = self.sample.lobe_scales(wi, wo) if self.integral.uses_scales else ONE_POINT
        return self.integral.integrate(self.sample.integrand, wi, wo, scales)

    def _far_from_peak(self, wi: np.ndarray, wo: np.ndarray) -> bool:
        """Whether wo lies more than twice the aperture's and beam's reach from the lobe's
        specular peak (or the lobe has none)."""
        peak = self.sample.peak_direction(wi, reflection=(wo[2] > 0) == (wi[2] > 0))
        reach = self.integral.aperture_rad + self.integral.divergence_rad
        return peak is None or math.acos(min(1.0, float(peak @ wo))) > 2.0 * reach

    def reduced_bsdf(self, sample_deg: np.ndarray, arm_deg: np.ndarray) -> np.ndarray:
        """What reduction of noiseless readings at these stage positions (true ones, taken as
        reported) gives: the scattered fraction over Omega T |cos o| (the exit view's factor
        T), so a test compares reduced values with the bench's exact expectation."""
        fraction = np.array([self.scattered_fraction({"sample": s, "arm": a})
                             for s, a in zip(sample_deg, arm_deg, strict=True)])
        wi, wo = sample_frame_directions({"sample": np.asarray(sample_deg, float),
                                          "arm": np.asarray(arm_deg, float)},
                                         flipped=self.sample.flipped)
        _, factor = exit_view(self.sample.spec, wi, wo)
        return fraction / (self.integral.solid_angle_sr * factor * np.abs(wo[..., 2]))

    def warm_up(self, at: Mapping[str, float] | None = None) -> None:
        """Build what the first reading needs before an emulated device has to answer: the
        model's compiled kernels (seconds on a fresh machine) and the multiple-scattering
        tables of one incidence, by a reading and its mirror across the sample (the arm turned
        half a turn: one reflected, one transmitted). The incidence is where the stages stand
        (`at`: reported positions by role; the alignment's offsets alone place them, no move's
        scatter is drawn), so nothing is built that the readings there do not need; a fixed
        WARM_UP_PLACE when that is unknown or the sample is out of the beam."""
        if at is None or self.retracted(at["sample"]):
            place: Mapping[str, float] = WARM_UP_PLACE
        else:
            place = self.alignment.placed(at)
        for turn in (0.0, 180.0):
            self.scattered_fraction({**place, "arm": place["arm"] + turn})

    def prepare(self, positions: Iterable[Mapping[str, float]],
                progress: tables.Progress | None = None) -> tables.TablesPrepared:
        """Build, before an emulated device has to answer, the multiple-scattering tables the
        readings at `positions` (reported stage positions by role: a plan's schedule) will
        need, and no other (sim.bench.tables.prepare); `progress` is told the planes walked."""
        return tables.prepare(self, positions, progress)

    def power_w(self, positions: Mapping[str, float], t_s: float = 0.0) -> float:
        """True optical power at the detector for reported stage positions at time t_s."""
        true = self.alignment.true_positions(positions)
        if self.retracted(true["sample"]):
            fraction = self.direct_beam_fraction(true["arm"], true["elevation"])
        else:
            fraction = self.scattered_fraction(true)
        fraction += self.stray.fraction(true["arm"], true["elevation"], self.integral.aperture_rad)
        return self.source.power_at(t_s) * fraction


class BenchPowerSource:
    """The PowerSource detector emulators ask: the bench at the stages' current positions."""

    def __init__(
        self,
        bench: Bench,
        positions: Callable[[], Mapping[str, float]],
        clock: Callable[[], float] | None = None,
    ):
        self.bench = bench
        self._positions = positions
        t0 = time.monotonic()
        self._clock = clock or (lambda: time.monotonic() - t0)

    def power_w(self) -> float:
        """True optical power at the detector now, W."""
        return self.bench.power_w(self._positions(), self._clock())

