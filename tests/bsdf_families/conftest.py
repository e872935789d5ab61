"""The families' tests share tests/bsdf's helpers (bsdf_quadrature: sphere quadrature and the
chi-square test of a sampler against its density; bsdf_reference: Walter's model in mpmath)."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bsdf"))
