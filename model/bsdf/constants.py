"""Identities and numeric constants shared by the scalar formulas (primitives.py) and their
vectorised numpy versions (distributions.py, masking.py, microfacet.py).

The IntEnums name what the compiled kernels tell apart: numba sees their members as ints. This
module imports nothing heavy, so that model.bsdf imports without starting numba."""

from __future__ import annotations

import math
from enum import IntEnum


class Ndf(IntEnum):
    """Normal distributions that have scalar formulas (Distribution.kernel names its own)."""

    GGX = 0
    BECKMANN = 1


class Masking(IntEnum):
    """Smith masking-shadowing forms (masking.py): G1(i) G1(o), or height-correlated."""

    SEPARABLE = 0
    CORRELATED = 1


class Sampling(IntEnum):
    """Normal-sampling schemes (microfacet.py): visible normals, or Walter's widened D m.z."""

    VISIBLE = 0
    WALTER = 1


def enum_names(kinds: type[IntEnum]) -> tuple[str, ...]:
    """The public names of an enum's members, in order: Masking -> ('separable', 'correlated')."""
    return tuple(kind.name.lower() for kind in kinds)


SQRT_PI = math.sqrt(math.pi)
#: Directions with |cos theta| at or below this count as grazing: eval returns 0 there (the
#: cosine-weighted value is 0; f itself may diverge for correlated masking at double grazing).
COS_HORIZON = 1e-100
#: Beckmann a*Lambda(a) switches from the closed form to a continued fraction at this a.
BECKMANN_CF_FROM = 2.0
#: Terms of the erfc continued fraction; enough for full float64 accuracy for a >= 2.
BECKMANN_CF_TERMS = 60
#: The compiled a*Lambda(a) keeps the closed form up to this a: its cancellation costs ~2a^2
#: ulps (2e-14 at most against mpmath), where the continued fraction needs 60 chained divisions
#: at a = 2 and 14-21 from here on (62 ns a call over walk directions, 117 ns with it from a = 2).
BECKMANN_KERNEL_CF_FROM = 5.0
#: Above this argument log Gamma is taken as Stirling's form plus STIRLING_TERMS corrections.
STIRLING_FROM = 10.0
#: Coefficients B_2k / (2k (2k - 1)) of the Stirling correction sum_k c_k / x^(2k - 1); at
#: x = 10 the first omitted term is 2e-18, below an ulp of every log Gamma it corrects.
STIRLING_TERMS = (1 / 12, -1 / 360, 1 / 1260, -1 / 1680, 1 / 1188, -691 / 360360, 1 / 156,
                  -3617 / 122400)
HALF_LOG_2PI = 0.5 * math.log(2.0 * math.pi)
#: Walter's (2007, eq. 47) roughness scale for sampling: WALTER_BASE - WALTER_SLOPE sqrt|cos i|.
WALTER_BASE = 1.2
WALTER_SLOPE = 0.2
