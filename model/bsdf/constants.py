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
#: ulps (2e-14 at most against mpmath); from here on it takes Cody's rational approximation of
#: erfc's tail (CODY_ERFC_P, CODY_ERFC_Q: 8e-16 relative against mpmath up to a = 26.5, ten
#: multiply-adds and a division where the continued fraction chained 14-21 divisions).
BECKMANN_KERNEL_TAIL_FROM = 5.0
#: W. J. Cody, "Rational Chebyshev approximations for the error function", Math. Comp. 23
#: (1969), the x >= 4 range as his CALERF takes it: erfc(x) = exp(-x^2) / x (1/sqrt(pi) - R),
#: R = z (P5 + z (P0 + z (... P4 ... ))) / (Q4 + ...) in z = 1/x^2 (cody_tail).
CODY_ERFC_P = (3.05326634961232344e-1, 3.60344899949804439e-1, 1.25781726111229246e-1,
               1.60837851487422766e-2, 6.58749161529837803e-4, 1.63153871373020978e-2)
CODY_ERFC_Q = (2.56852019228982242e00, 1.87295284992346725e00, 5.27905102951428412e-1,
               6.05183413124413191e-2, 2.33520497626869185e-3)
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
