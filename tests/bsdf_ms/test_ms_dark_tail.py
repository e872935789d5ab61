"""The dark tail of issue 36: Beckmann 0.3 glass lit from air at 85 deg, seen at (0, 0.5,
-0.866). Order 2 there by an independent adaptive quadrature (second_order_reference) against
second_order (docs/multiple-scattering.md, "The dark tail")."""

import numpy as np
import pytest

from model.bsdf import RoughDielectric
from model.bsdf.multiple_scattering import RandomWalkBSDF
from model.bsdf.multiple_scattering.second_order import second_order
from tests.bsdf_ms.second_order_reference import SecondOrder

WI = np.array([np.sin(np.radians(85.0)), 0.0, np.cos(np.radians(85.0))])
WO = np.array([0.0, 0.5, -np.sqrt(0.75)])
#: Order 2 of f |cos o| at the pair by second_order_reference (both lobes; the reflected one
#: is exactly 0), stable to 1e-12 between EPSREL 1e-6 and 1e-9 (test_reference_at_the_dark_pair).
EXACT = 6.388034614910e-21


def _walker(name="beckmann", alpha=0.3):
    return RandomWalkBSDF(RoughDielectric(name, alpha, 1.51, masking="correlated"),
                          guided=False).walker


def test_second_order_converges_to_the_exact_value():
    """The compiled quadrature at 12 polar and 9 azimuth nodes per radian and 3x and 9x that:
    0.12 % low, 8e-8 and 1.5e-13 from the exact value (the lobe is narrow: the graded cells
    hold it)."""
    walker = _walker()
    for scale, rel in ((1, 0.06), (3, 2e-5), (9, 1e-9)):
        value = second_order(walker, WI, WO[None], polar=12 * scale, azimuth=9 * scale)[0]
        assert value == pytest.approx(EXACT, rel=rel, abs=0.0)


@pytest.mark.slow
def test_reference_at_the_dark_pair():
    """The independent quadrature: its reflected lobe is 0 (no facet reflects light arriving
    at 85 deg steeply enough down for a refraction to reach wo), the transmitted one EXACT."""
    reference = SecondOrder("beckmann", 0.3, 1.51, WI, WO)
    assert reference.lobe(False) == (0.0, 0.0)
    value, error = reference.lobe(True)
    assert value == pytest.approx(EXACT, rel=1e-9, abs=0.0)
    assert error < 1e-7 * value


@pytest.mark.slow
def test_reference_matches_second_order_at_a_bright_pair():
    """GGX 0.5 glass from 30 deg to 150 deg, 60 deg out of the plane (both lobes contribute):
    the independent quadrature against the compiled one at 3x its default nodes, within
    1e-6."""
    t, p = np.radians(150.0), np.radians(60.0)
    wi = np.array([np.sin(np.radians(30.0)), 0.0, np.cos(np.radians(30.0))])
    wo = np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])
    reference = SecondOrder("ggx", 0.5, 1.51, wi, wo)
    reflected, transmitted = reference.lobe(False)[0], reference.lobe(True)[0]
    compiled = second_order(_walker("ggx", 0.5), wi, wo[None], polar=36, azimuth=27)[0]
    assert reflected > 0.0 and transmitted > 0.0
    assert reflected + transmitted == pytest.approx(compiled, rel=1e-6, abs=0.0)
