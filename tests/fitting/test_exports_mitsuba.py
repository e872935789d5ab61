"""The Mitsuba export against Mitsuba 3 itself: the exported material, loaded by Mitsuba's own
parser and evaluated in its scalar variant, gives gonio's model (Walter's radiance BTDF) with
the camera in the detector's place, and gonio's times 1/eta^2 with the camera on the source's
side (the BTDF's reciprocity across the index change), as calibration.exports.model states;
reflection agrees either way."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from calibration.exports.mitsuba import material_parameters, write_mitsuba
from model.bsdf import RoughDielectric

mi = pytest.importorskip("mitsuba", reason="Mitsuba 3 is the `mitsuba` extra (in `test`)")
ETA, ALPHA = 1.51, 0.3


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    """The exported material as Mitsuba loads it (scalar_rgb)."""
    mi.set_variant("scalar_rgb")
    path = write_mitsuba(material_parameters("ggx", ALPHA, ETA),
                         tmp_path_factory.mktemp("mitsuba") / "glass.xml", ["test"])
    root = ET.parse(path).getroot()
    bsdf = root.find("bsdf")
    bsdf.set("version", root.get("version"))
    return mi.load_string(ET.tostring(bsdf, encoding="unicode"))


def mitsuba_f(bsdf, toward_camera: np.ndarray, toward_light: np.ndarray) -> float:
    """Mitsuba's BSDF value in radiance mode, without its cosine factor: eval() returns
    f |cos| of the direction toward the light."""
    si = mi.SurfaceInteraction3f()
    si.wi = mi.Vector3f(*toward_camera)
    si.sh_frame = mi.Frame3f(mi.Vector3f(0.0, 0.0, 1.0))
    value = bsdf.eval(mi.BSDFContext(mi.TransportMode.Radiance), si,
                      mi.Vector3f(*toward_light))
    return float(value[0]) / abs(float(toward_light[2]))


@pytest.mark.parametrize("theta_i,theta_o", [(0.0, 10.0), (30.0, 25.0), (60.0, 45.0),
                                             (75.0, 35.0)])
def test_mitsuba_transmission_is_gonio_btdf_and_one_over_eta_squared(exported, theta_i,
                                                                     theta_o):
    ti, to = math.radians(theta_i), math.radians(theta_o)
    source = np.array([-math.sin(ti), 0.0, math.cos(ti)])
    detector = np.array([math.sin(to), 0.0, -math.cos(to)])
    gonio = float(RoughDielectric("ggx", ALPHA, eta=ETA).eval(source[None], detector[None])[0])
    assert gonio > 0
    assert mitsuba_f(exported, detector, source) == pytest.approx(gonio, rel=1e-5)
    assert mitsuba_f(exported, source, detector) == pytest.approx(gonio / ETA**2, rel=1e-5)
    reflected = detector * np.array([1.0, 1.0, -1.0])
    f_r = float(RoughDielectric("ggx", ALPHA, eta=ETA).eval(source[None], reflected[None])[0])
    assert mitsuba_f(exported, reflected, source) == pytest.approx(f_r, rel=1e-5)
    assert mitsuba_f(exported, source, reflected) == pytest.approx(f_r, rel=1e-5)
