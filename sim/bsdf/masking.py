"""Smith masking-shadowing G2 of a pair of directions: separable (Walter) or height-correlated.

Everything is written divided by the two cosines, G2 / (|cos i| |cos o|), from the finite
quantities |cos| and |cos| Lambda, so grazing directions give finite limits instead of 0/0."""

from __future__ import annotations

import numpy as np

MASKINGS = ("separable", "correlated")


def check_masking(masking: str) -> str:
    """Return masking if it names a supported scheme, else raise a ValueError naming it."""
    if masking not in MASKINGS:
        raise ValueError(f"masking must be one of {MASKINGS}, got {masking!r}")
    return masking


def g2_over_cosines(
    masking: str, ci: np.ndarray, co: np.ndarray, li: np.ndarray, lo: np.ndarray
) -> np.ndarray:
    """G2(i, o) / (ci co) from ci = |cos i|, co = |cos o| and li, lo = |cos| Lambda.

    separable: G1(i) G1(o) = ci co / ((ci + li)(co + lo));
    correlated: 1 / (1 + Lambda_i + Lambda_o) = ci co / (ci co + co li + ci lo).
    """
    if masking == "separable":
        return 1.0 / ((ci + li) * (co + lo))
    return 1.0 / (ci * co + co * li + ci * lo)
