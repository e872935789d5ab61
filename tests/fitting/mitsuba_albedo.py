"""Mitsuba 3's own directional albedo of a material gonio exported: the XML loaded by Mitsuba's
parser (the gonio_multiscatter plugin, when the export wrote it, imported from beside the XML
and registered), its bsdf.sample() run in importance mode (si.wi toward the light) over many
samples, the weights summed by the side wo leaves on. For the tests and bench/mitsuba_albedo.py;
needs Mitsuba's llvm_ad_rgb variant."""

from __future__ import annotations

import importlib.util
import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

VARIANT = "llvm_ad_rgb"
PLUGIN_MODULE = "gonio_mitsuba_plugin"


def load_material(path: str | Path, variant: str = VARIANT):
    """The exported BSDF as Mitsuba's own parser loads it, in `variant`; the plugin beside the
    XML, if there is one, imported and registered first."""
    import mitsuba as mi

    path = Path(path)
    mi.set_variant(variant)
    plugin = path.with_name(f"{PLUGIN_MODULE}.py")
    if plugin.exists():
        spec = importlib.util.spec_from_file_location(PLUGIN_MODULE, plugin)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        module.register()
    bsdf = ET.parse(path).getroot().find("bsdf")
    bsdf.set("version", "3.0.0")
    return mi.load_string(ET.tostring(bsdf, encoding="unicode"))


def mitsuba_albedo(bsdf, theta_deg: float, samples: int, seed: int = 7
                   ) -> tuple[float, float, float]:
    """(R, T, standard error of R + T) of light arriving at theta_deg from outside (+z)."""
    import drjit as dr
    import mitsuba as mi

    u = np.random.default_rng(seed).random((3, samples)).astype(np.float32)
    t = math.radians(theta_deg)
    si = dr.zeros(mi.SurfaceInteraction3f, samples)
    si.wi = mi.Vector3f(math.sin(t), 0.0, math.cos(t))
    si.sh_frame = mi.Frame3f(mi.Vector3f(0.0, 0.0, 1.0))
    sample, weight = bsdf.sample(mi.BSDFContext(mi.TransportMode.Importance), si,
                                 mi.Float(u[0]), mi.Point2f(mi.Float(u[1]), mi.Float(u[2])))
    w = np.array(weight.x)
    up = np.array(sample.wo)[2] > 0
    return (float(np.mean(np.where(up, w, 0.0))), float(np.mean(np.where(up, 0.0, w))),
            float(np.std(w) / math.sqrt(samples)))


def render_white_furnace(path: str | Path) -> np.ndarray:
    """A 16 x 16 render (VARIANT, path tracing) of a sphere of the exported material under a
    uniform white sky: every pixel sees at most the light that comes in."""
    import mitsuba as mi

    path = Path(path)
    load_material(path)  # sets the variant and registers the plugin
    scene = path.with_name("scene.xml")
    scene.write_text(f"""<scene version="3.0.0">
  <include filename="{path.name}"/>
  <integrator type="path"><integer name="max_depth" value="8"/></integrator>
  <sensor type="perspective">
    <transform name="to_world"><lookat origin="0, 0, 4" target="0, 0, 0" up="0, 1, 0"/>
    </transform>
    <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="16"/>
    </film>
    <sampler type="independent"><integer name="sample_count" value="16"/></sampler>
  </sensor>
  <emitter type="constant"/>
  <shape type="sphere"><ref id="gonio_sample"/></shape>
</scene>
""")
    return np.array(mi.render(mi.load_file(str(scene))))
