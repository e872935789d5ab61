"""Detector physics shared by the emulated power meters: true optical power -> reported reading.

A detector emulator (PM100 SCPI, Modbus amplifier + ADC) asks a `PowerSource` for the true
optical power at the detector and passes it through a `PhotodiodeModel`: silicon responsivity
at the light's wavelength, the device's wavelength correction, gain ranges with autoranging,
ADC clipping (the saturation flag) and quantisation, dark current, stray light, shot and read
noise, and averaging of N samples. Every random draw is seeded (reproducible noise, below).

Noise and averaging: each of the N averaged samples carries independent shot noise
(std sqrt(2 q I B) in current, I the total photocurrent, B `bandwidth_hz`) and read noise
(`read_noise_fraction` x full scale of the range), and is quantised by the range's ADC step.
The reported mean therefore has a standard deviation that falls as 1/sqrt(N); quantisation
adds step/sqrt(12) per sample, which the noise dithers, so it also averages down as 1/sqrt(N)
as long as the per-sample noise is at least about one step (`expected_sigma_w`).

Reproducible noise: a measurement's draws do not come from one stream in call order (where a
retried request or a resumed run would shift every later reading) but from a generator of its
own, keyed on the seed (one per device), the place it is taken at (the commanded stage
positions, in millidegrees), the range setting (autorange or a fixed range) and the
visit count: how many measurements this meter has taken at that place and range before.
`visited` counts measurements taken before this process (a resumed run's stored readings).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Mapping, Sequence
from typing import NamedTuple, Protocol, runtime_checkable

import numpy as np

ELEMENTARY_CHARGE_C = 1.602176634e-19

# Typical responsivity of a silicon photodiode (A/W) against wavelength (nm), as in power
# meter sensor datasheets; linear interpolation between the points, clamped at the ends.
SILICON_RESPONSIVITY = np.array(
    [
        [350.0, 0.10], [400.0, 0.15], [450.0, 0.21], [500.0, 0.27], [550.0, 0.32],
        [600.0, 0.37], [650.0, 0.42], [700.0, 0.46], [750.0, 0.50], [800.0, 0.53],
        [850.0, 0.56], [900.0, 0.59], [950.0, 0.61], [1000.0, 0.55], [1050.0, 0.36],
        [1100.0, 0.18],
    ]
)

PLACE_STEPS_PER_DEG = 1000  # a place key counts millidegrees, as the Modbus drives do

DEFAULT_RANGES_W = (1e-8, 1e-7, 1e-6, 1e-5, 1e-4, 1e-3, 1e-2)

# [sim.detector] keys, their defaults and what they are (docs/bench.md repeats this table).
DETECTOR_DEFAULTS: dict[str, object] = {
    "responsivity": "silicon",  # "silicon", a number in A/W, or [[nm, A/W], ...]
    "ranges_w": list(DEFAULT_RANGES_W),  # full-scale power of each gain range, W
    "adc_bits": 16,  # ADC resolution over [-overrange, +overrange] x full scale
    "overrange": 1.1,  # the ADC clips (saturated flag) at this multiple of full scale
    "autorange_fill": 0.9,  # autorange picks the smallest range with signal <= fill x FS
    "dark_current_a": 2e-11,  # photodiode dark current, A (an offset until zeroed)
    "stray_light_w": 0.0,  # constant background optical power reaching the detector, W
    "read_noise_fraction": 1e-4,  # amplifier + ADC noise per sample, fraction of full scale
    "bandwidth_hz": 1000.0,  # noise bandwidth of one sample (sets the shot noise)
    "range_gains": None,  # per range: true gain / nominal (amplifier error); None = all 1
}


class SimConfigError(ValueError):
    """A [sim] table of an instrument config is invalid; the message names the field."""


@runtime_checkable
class PowerSource(Protocol):
    """Anything that knows the true optical power at the detector right now."""

    def power_w(self) -> float:
        """True optical power arriving at the detector now, W."""


class ConstantPower:
    """A PowerSource that always returns the same power (tests, a bench without physics)."""

    def __init__(self, power_w: float):
        if not np.isfinite(power_w) or power_w < 0:
            raise ValueError(f"ConstantPower: power_w must be finite and >= 0, got {power_w!r}")
        self._power_w = float(power_w)

    def power_w(self) -> float:
        """The fixed power, W."""
        return self._power_w


class Measurement(NamedTuple):
    """What the meter reports: the (averaged) power reading, the range used, the clip flag."""

    reading_w: float
    range_w: float
    saturated: bool


def _number(table: Mapping, key: str, low: float, high: float = np.inf) -> float:
    value = table[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise SimConfigError(f"[sim.detector] {key}: must be a number, got {value!r}")
    if not (low <= value <= high) or not np.isfinite(value):
        raise SimConfigError(f"[sim.detector] {key}: must be in [{low:g}, {high:g}], got {value!r}")
    return float(value)


def _responsivity_table(value: object) -> np.ndarray:
    if value == "silicon":
        return SILICON_RESPONSIVITY
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        if not value > 0:
            raise SimConfigError(f"[sim.detector] responsivity: must be > 0 A/W, got {value!r}")
        return np.array([[0.0, float(value)], [1.0, float(value)]])
    try:
        table = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        table = np.empty(0)
    ok = (
        table.ndim == 2 and table.shape[1:] == (2,) and len(table) >= 2
        and np.all(np.diff(table[:, 0]) > 0) and np.all(table[:, 1] > 0)
    )
    if not ok:
        raise SimConfigError(
            '[sim.detector] responsivity: must be "silicon", a number in A/W, or a list of '
            f"[wavelength_nm, A_per_W] pairs with increasing wavelength, got {value!r}"
        )
    return table


def _range_gains(value: object, n_ranges: int) -> np.ndarray:
    """Per-range gain errors (None: 1 on every range); one factor in [0.5, 2] per range."""
    if value is None:
        return np.ones(n_ranges)
    try:
        gains = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        gains = np.empty(0)
    if gains.shape != (n_ranges,) or not np.all((gains >= 0.5) & (gains <= 2.0)):
        raise SimConfigError(
            f"[sim.detector] range_gains: must be a list of {n_ranges} factors in [0.5, 2], "
            f"one per range of ranges_w, got {value!r}"
        )
    return gains


class PhotodiodeModel:
    """A photodiode power meter: true power (W) -> reading (W), range (W), saturated flag.

    `measure` draws `averaging` samples, each with shot and read noise and ADC quantisation of
    its range, and returns their mean; noise std of the mean scales as 1/sqrt(averaging).
    """

    def __init__(
        self,
        config: Mapping | None = None,
        seed: int = 0,
        light_wavelength_nm: float | None = None,
    ):
        """config: the [sim.detector] table (missing keys take DETECTOR_DEFAULTS); seed: the
        noise's seed (one per device); light_wavelength_nm: the light's true wavelength (None =
        whatever correction wavelength the device is set to, i.e. a perfectly corrected meter)."""
        table = dict(config or {})
        unknown = sorted(set(table) - set(DETECTOR_DEFAULTS))
        if unknown:
            raise SimConfigError(
                f"[sim.detector]: unknown key {unknown[0]!r}; known: {', '.join(DETECTOR_DEFAULTS)}"
            )
        table = {**DETECTOR_DEFAULTS, **table}
        self._responsivity = _responsivity_table(table["responsivity"])
        ranges = table["ranges_w"]
        try:
            ranges_arr = np.asarray(ranges, dtype=np.float64)
        except (TypeError, ValueError):
            ranges_arr = np.empty(0)
        if ranges_arr.ndim != 1 or len(ranges_arr) == 0 or np.any(~(ranges_arr > 0)) or np.any(
            np.diff(ranges_arr) <= 0
        ):
            raise SimConfigError(
                f"[sim.detector] ranges_w: must be a non-empty increasing list of powers > 0 W, "
                f"got {ranges!r}"
            )
        self._ranges = tuple(float(r) for r in ranges_arr)
        self._gains = _range_gains(table["range_gains"], len(self._ranges))
        bits = table["adc_bits"]
        if isinstance(bits, bool) or not isinstance(bits, int) or not 4 <= bits <= 32:
            raise SimConfigError(
                f"[sim.detector] adc_bits: must be an integer in [4, 32], got {bits!r}"
            )
        self.adc_bits = bits
        self.overrange = _number(table, "overrange", 1.0, 10.0)
        self.autorange_fill = _number(table, "autorange_fill", 0.01, 1.0)
        self.dark_current_a = _number(table, "dark_current_a", 0.0)
        self.stray_light_w = _number(table, "stray_light_w", 0.0)
        self.read_noise_fraction = _number(table, "read_noise_fraction", 0.0, 1.0)
        self.bandwidth_hz = _number(table, "bandwidth_hz", 0.0)
        if light_wavelength_nm is not None and not light_wavelength_nm > 0:
            raise SimConfigError(f"light wavelength must be > 0 nm, got {light_wavelength_nm!r}")
        self.light_wavelength_nm = light_wavelength_nm
        self.zero_offset_w = 0.0
        self.seed = int(seed) % (1 << 64)  # SeedSequence takes unsigned words
        self._visits: Counter[tuple[int, ...]] = Counter()

    @property
    def ranges_w(self) -> tuple[float, ...]:
        """Full-scale power of each gain range, W, increasing (for SCPI / Modbus range settings)."""
        return self._ranges

    def responsivity_a_w(self, wavelength_nm: float) -> float:
        """Photodiode responsivity at a wavelength, A/W."""
        table = self._responsivity
        return float(np.interp(wavelength_nm, table[:, 0], table[:, 1]))

    def range_for(self, power_w: float) -> float:
        """The smallest range whose full scale holds power_w (the largest if none does):
        what a meter does with a 'set range to P' command."""
        for full_scale in self._ranges:
            if power_w <= full_scale:
                return full_scale
        return self._ranges[-1]

    def gain(self, range_w: float) -> float:
        """True gain of a range relative to its nominal one (`range_gains`; 1 if not given)."""
        return float(self._gains[self._ranges.index(range_w)])

    def adc_step_w(self, range_w: float) -> float:
        """One ADC count in W on a range: the span [-overrange, +overrange] x FS over 2^bits."""
        return 2.0 * self.overrange * range_w / 2.0**self.adc_bits

    def zero(self, wavelength_nm: float) -> None:
        """Dark-zero adjustment: from now on subtract the mean dark + stray reading (light off)."""
        self.zero_offset_w = 0.0
        self.zero_offset_w = self._mean_reading_w(0.0, wavelength_nm)

    def _light_nm(self, wavelength_nm: float) -> float:
        return wavelength_nm if self.light_wavelength_nm is None else self.light_wavelength_nm

    def _photocurrent_a(self, power_w: float, wavelength_nm: float) -> float:
        light = self.responsivity_a_w(self._light_nm(wavelength_nm))
        return light * (power_w + self.stray_light_w) + self.dark_current_a

    def _mean_reading_w(self, power_w: float, wavelength_nm: float, gain: float = 1.0) -> float:
        """Noise-free reading: photocurrent over the responsivity at the set wavelength, times
        the range's gain error, less the zero offset."""
        current = self._photocurrent_a(power_w, wavelength_nm)
        return gain * current / self.responsivity_a_w(wavelength_nm) - self.zero_offset_w

    def autorange(self, power_w: float, wavelength_nm: float) -> float:
        """The range autoranging settles on: smallest with mean reading <= autorange_fill x FS."""
        for full_scale, gain in zip(self._ranges, self._gains, strict=True):
            mean = self._mean_reading_w(power_w, wavelength_nm, gain)
            if mean <= self.autorange_fill * full_scale:
                return full_scale
        return self._ranges[-1]

    def sample_sigma_w(self, power_w: float, range_w: float, wavelength_nm: float) -> float:
        """Standard deviation of one sample before quantisation, W: shot (+) read noise."""
        current = self._photocurrent_a(power_w, wavelength_nm)
        shot_a = np.sqrt(2.0 * ELEMENTARY_CHARGE_C * max(current, 0.0) * self.bandwidth_hz)
        shot_w = self.gain(range_w) * shot_a / self.responsivity_a_w(wavelength_nm)
        read_w = self.read_noise_fraction * range_w
        return float(np.hypot(shot_w, read_w))

    def expected_sigma_w(
        self, power_w: float, range_w: float, averaging: int, wavelength_nm: float
    ) -> float:
        """Predicted standard deviation of a reading: sqrt(sample^2 + step^2 / 12) / sqrt(N).

        Valid while the per-sample noise dithers the ADC (sample sigma >~ one step)."""
        per_sample = np.hypot(self.sample_sigma_w(power_w, range_w, wavelength_nm),
                              self.adc_step_w(range_w) / np.sqrt(12.0))
        return float(per_sample / np.sqrt(averaging))

    def _reading_key(self, place: Sequence[float], range_w: float | None) -> tuple[int, ...]:
        """What identifies a measurement but its visit count: the place (stage positions in
        millidegrees, as unsigned 64-bit words) and the range setting (0 = autorange, else
        the range's number from 1)."""
        steps = (round(deg * PLACE_STEPS_PER_DEG) % (1 << 64) for deg in place)
        setting = 0 if range_w is None else self._ranges.index(self.range_for(range_w)) + 1
        return len(place), *steps, setting

    def visited(self, place: Sequence[float], range_w: float | None) -> None:
        """Count a measurement taken at place with the range setting range_w (None =
        autorange) before this meter existed: a resumed run's stored reading."""
        self._visits[self._reading_key(place, range_w)] += 1

    def forget(self, place: Sequence[float], range_w: float | None) -> None:
        """Uncount the last measurement at place and range setting range_w: the client threw
        it away (a run stores the reading again), so later readings there keep the noise an
        undisturbed run gives them."""
        key = self._reading_key(place, range_w)
        if self._visits[key] > 0:
            self._visits[key] -= 1

    def _generator(self, place: Sequence[float], range_w: float | None) -> np.random.Generator:
        """The noise generator of the next measurement at place and range setting range_w."""
        key = self._reading_key(place, range_w)
        visit = self._visits[key]
        self._visits[key] += 1
        return np.random.default_rng(np.random.SeedSequence([self.seed, *key, visit]))

    def measure(
        self,
        power_w: float,
        range_w: float | None = None,
        averaging: int = 1,
        wavelength_nm: float = 632.8,
        place: Sequence[float] = (),
    ) -> Measurement:
        """One reading of the true power power_w (W): range_w one of `ranges_w` or None for
        autoranging; averaging the number of samples averaged (>= 1); wavelength_nm the
        correction wavelength the device is set to; place the commanded stage positions, deg
        (keys the noise with the range setting and the visit count; () = anywhere)."""
        if not np.isfinite(power_w) or power_w < 0:
            raise ValueError(f"measure: power_w must be finite and >= 0, got {power_w!r}")
        if isinstance(averaging, bool) or int(averaging) != averaging or averaging < 1:
            raise ValueError(f"measure: averaging must be an integer >= 1, got {averaging!r}")
        if not wavelength_nm > 0:
            raise ValueError(f"measure: wavelength_nm must be > 0, got {wavelength_nm!r}")
        if range_w is not None and range_w not in self._ranges:
            raise ValueError(f"measure: range_w {range_w!r} is not one of {self._ranges}")
        rng = self._generator(place, range_w)
        if range_w is None:
            range_w = self.autorange(power_w, wavelength_nm)
        mean = self._mean_reading_w(power_w, wavelength_nm, self.gain(range_w))
        sigma = self.sample_sigma_w(power_w, range_w, wavelength_nm)
        samples = mean + sigma * rng.standard_normal(int(averaging))
        clip = self.overrange * range_w
        saturated = bool(np.any(np.abs(samples) >= clip))
        step = self.adc_step_w(range_w)
        counts = np.clip(np.round(samples / step), -(clip / step), clip / step)
        return Measurement(float(np.mean(counts) * step), float(range_w), saturated)
