"""A virtual clock that moves only when read: a test decides how far each read moves it, so
a move's progress counts reads (polls, round trips), not real seconds."""

from __future__ import annotations

from sim.devices.motion import VirtualClock


class TickingClock(VirtualClock):
    """A frozen clock that moves on by `step` virtual seconds whenever it is read."""

    def __init__(self, step: float):
        super().__init__(0.0)
        self.step = step

    def now(self) -> float:
        """Virtual time after this read's step."""
        return self.advance(self.step)
