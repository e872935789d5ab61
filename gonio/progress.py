"""Progress bar for a scan (tqdm on stderr): readings done, rate, ETA and the current angles;
a subscriber of the engine's events (gonio.events)."""

from __future__ import annotations

import sys
from typing import Any

from tqdm import tqdm

from gonio.events import ReadingStored, Stopping


class Progress:
    """A tqdm bar that starts at the readings already done (a resumed run) and shows angles."""

    def __init__(self, total: int, done: int = 0, description: str = "scan",
                 disable: bool | None = None):
        """disable: True hides the bar, None shows it only on a terminal (tqdm's rule)."""
        self._bar = tqdm(total=total, initial=done, desc=description, unit="pt",
                         file=sys.stderr, dynamic_ncols=True, disable=disable,
                         smoothing=0.1)

    def __call__(self, event: Any) -> None:
        """Count a stored reading; close at the end of the run."""
        if isinstance(event, ReadingStored):
            self.update(event.record)
        elif isinstance(event, Stopping):
            self.close()

    def update(self, row: dict[str, Any]) -> None:
        """Count one reading and show where the stages are."""
        angles = (f"{row['kind']} s={row['sample_deg']:.2f} a={row['arm_deg']:.2f}"
                  f" e={row['elevation_deg']:.2f} p={row['azimuth_deg']:.2f}")
        self._bar.set_postfix_str(angles, refresh=False)
        self._bar.update(1)

    def close(self) -> None:
        """Finish the bar."""
        self._bar.close()


class TablesProgress:
    """The emulated bench's table building before a scan's first move (sim.bench.tables): a
    tqdm bar of planes walked of planes to walk, with the time left, made at the first call
    (so nothing shows when every plane is cached)."""

    def __init__(self, walks: int, disable: bool | None = None):
        """walks: walks per plane (for the label); disable: as Progress's."""
        self._walks, self._disable = walks, disable
        self._bar: tqdm | None = None

    def __call__(self, walked: int, to_walk: int) -> None:
        """Show `walked` planes of `to_walk`; close the bar when they are all walked."""
        if self._bar is None:
            self._bar = tqdm(total=to_walk, desc=f"multiple-scattering tables ({self._walks} "
                             f"walks a plane)", unit="plane", file=sys.stderr,
                             dynamic_ncols=True, disable=self._disable, smoothing=0.3)
        self._bar.total = to_walk
        self._bar.update(walked - self._bar.n)
        if walked == to_walk:
            self._bar.close()
