"""Summaries over seeds for the benches' error-against-run-time tables: one draw of a Monte
Carlo error says little (heavy tails), so each row is the median of SEEDS draws with its range;
a deterministic approximation's table says so in its heading instead."""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

#: Independent seeds per row of a stochastic approximation's error table.
SEEDS = 8
#: The heading of a deterministic approximation's table, which has no seeds to draw.
DETERMINISTIC = "deterministic (no random draws): one run is exact, its spread over seeds 0"


def median_range(values: Iterable[float], spec: str = ".5f") -> str:
    """'median [min, max]' of one row's values over seeds, each formatted with spec."""
    v = np.asarray(list(values), dtype=np.float64)
    low, mid, high = np.min(v), np.median(v), np.max(v)
    return f"{mid:{spec}} [{low:{spec}}, {high:{spec}}]"

