"""The emulator's truth of an all-emulated run, as the composition root provides it.

calibration never imports sim: gonio's command line and live view install sim.truth's
EmulatorTruth here (`provide`) at start-up, and reduction and plots ask `truth_of` for the [sim]
table that gonio.record.emulator_config gave them (None for any run with a real device). With
no provider installed an all-emulated run is reduced as a real one would be."""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from typing import TYPE_CHECKING, Protocol

if TYPE_CHECKING:  # the command line installs the provider at start-up: nothing heavy here
    import numpy as np


class EmulatorTruth(Protocol):
    """What reduction and plots show of the emulator: the sample it emulated (distribution,
    alpha, eta, masking), its meter's shot noise, and the bench's own BSDF curves."""

    sample: dict

    def shot_noise_w(self, wavelength_nm: float) -> float:
        """Shot-noise variance of one meter sample per watt of signal, W^2/W."""

    def curves(self, theta_i_deg: float, transmission: bool, aperture_half_angle_deg: float
               ) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """{label: (signed theta_o deg, BSDF)} in the plane of incidence."""


#: (sim table, [optics], plan [sample]) -> EmulatorTruth; raises ValueError on a bad field.
Provider = Callable[[Mapping, Mapping | None, Mapping | None], EmulatorTruth]
_providers: list[Provider] = []


def provide(provider: Provider) -> None:
    """Install the emulator's truth (the composition root calls this once)."""
    _providers[:] = [provider]


def truth_of(sim: Mapping | None, optics: Mapping | None = None,
             sample: Mapping | None = None) -> EmulatorTruth | None:
    """The truth of an all-emulated run's [sim] table (None: not all emulated, or no provider);
    a bad [sim] field is a CalibrationError naming it."""
    if not sim or not _providers:
        return None
    with run_config_errors():
        return _providers[0](sim, optics, sample)


@contextmanager
def run_config_errors() -> Iterator[None]:
    """A bad [sim] field that the truth meets (its ValueError) as a CalibrationError naming it:
    on building the truth, and on asking it what it reads only when asked (the meter)."""
    from calibration.values import CalibrationError

    try:
        yield
    except ValueError as exc:
        raise CalibrationError(f"run config: {exc}") from None
