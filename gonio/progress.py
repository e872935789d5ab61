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
