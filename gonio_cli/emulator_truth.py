"""The composition root's hand-over of the emulator's truth: calibration never imports sim, so
the command line installs sim.truth's EmulatorTruth into calibration.emulator_truth once, and
sim loads only when an all-emulated run is reduced or plotted."""

from __future__ import annotations

from collections.abc import Mapping

from calibration.emulator_truth import EmulatorTruth, provide


def emulator_truth(sim: Mapping, optics: Mapping | None, sample: Mapping | None
                   ) -> EmulatorTruth:
    """sim.truth.EmulatorTruth of an all-emulated run's [sim] table (imported on first use)."""
    from sim.truth import EmulatorTruth as SimTruth

    return SimTruth(sim, optics, sample)


def install() -> None:
    """Hand the emulator's truth to calibration (gonio_cli.main does this at start-up)."""
    provide(emulator_truth)
