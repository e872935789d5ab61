"""Mitsuba 3 material from a fit: a `roughdielectric` (or `roughconductor`) BSDF in a scene
fragment, with the fitted distribution, alpha (or alpha_u / alpha_v) and index.

Mitsuba 3 knows Beckmann and GGX only: a Phong fit is written as the Beckmann distribution of
the same alpha (Walter's mapping makes them agree for narrow lobes) and says so in a comment.
Mitsuba's masking is the separable Smith form; a fit that preferred the height-correlated form
is noted likewise. A fitted scale factor goes to specular_reflectance / specular_transmittance.
A fit with multiple scattering is written as the `gonio_multiscatter` plugin
(calibration.exports.mitsuba_plugin, copied beside the XML as PLUGIN_FILE) around that BSDF, its
tables the reflectance and transmittance that the BSDF lacks.
"""

from __future__ import annotations

import shutil
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from pathlib import Path
from typing import Any

SCENE_VERSION = "3.0.0"
#: Parameters written as `<rgb>` (Mitsuba's spectra and textures); the others are floats.
RGB_PARAMETERS = ("specular_reflectance", "specular_transmittance", "eta", "k", "reflectance",
                  "diffuse_reflectance")
#: The plugin's file name beside an export that needs it, and its type in the XML.
PLUGIN_FILE = "gonio_mitsuba_plugin.py"
PLUGIN_TYPE = "gonio_multiscatter"
#: The plugin's tables (mitsuba_plugin.TABLES: reflectance and transmittance of light arriving
#: from outside and from inside).
PLUGIN_TABLES = ("reflectance_outside", "transmittance_outside", "reflectance_inside",
                 "transmittance_inside")
#: How a script renders an export that names the plugin (a scene file cannot load it itself).
PLUGIN_USE = (f"render from Python: mitsuba.set_variant(...), then import {PLUGIN_FILE[:-3]} "
              f"(beside this file) and call {PLUGIN_FILE[:-3]}.register() before "
              "mitsuba.load_file; the `mitsuba` command cannot load it")


def material_parameters(distribution: str, alpha: float | tuple[float, float], eta: float,
                        scale: float = 1.0, conductor_k: float | None = None) -> dict[str, Any]:
    """The plugin type and parameters Mitsuba needs, from fitted values."""
    params: dict[str, Any] = {"distribution": "beckmann" if distribution == "phong" else
                              distribution}
    if isinstance(alpha, tuple):
        params["alpha_u"], params["alpha_v"] = float(alpha[0]), float(alpha[1])
    else:
        params["alpha"] = float(alpha)
    if conductor_k is None:
        params.update(int_ior=float(eta), ext_ior=1.0)
        if scale != 1.0:
            params["specular_reflectance"] = params["specular_transmittance"] = float(scale)
        return {"type": "roughdielectric", "params": params}
    params.update(eta=float(eta), k=float(conductor_k))
    if scale != 1.0:
        params["specular_reflectance"] = float(scale)
    return {"type": "roughconductor", "params": params}


def listed(values: Sequence[float], digits: int = 6) -> str:
    """Numbers as a plugin's comma-separated list property."""
    return ", ".join(f"{float(v):.{digits}g}" for v in values)


def plugin_material(single: dict[str, Any], ior: float, theta_deg: Sequence[float],
                    tables: dict[str, Sequence[float]]) -> dict[str, Any]:
    """The `gonio_multiscatter` material around the single-scattering one: its tables (names
    as mitsuba_plugin.TABLES) at the angles theta_deg, and the index of transmitted light."""
    params: dict[str, Any] = {"ior": float(ior), "theta_deg": listed(theta_deg)}
    params.update({name: listed(values) for name, values in tables.items()})
    return {"type": PLUGIN_TYPE, "params": params, "nested": {"single": single}}


def _add_bsdf(parent: ET.Element, material: dict[str, Any], **attributes: str) -> None:
    """A `<bsdf type=...>` element with typed parameters and any nested BSDFs."""
    bsdf = ET.SubElement(parent, "bsdf", type=material["type"], **attributes)
    for name, value in material["params"].items():
        if isinstance(value, str):
            ET.SubElement(bsdf, "string", name=name, value=value)
        elif name in RGB_PARAMETERS:
            ET.SubElement(bsdf, "rgb", name=name, value=f"{value:.9g}")
        else:
            ET.SubElement(bsdf, "float", name=name, value=f"{value:.9g}")
    for name, nested in material.get("nested", {}).items():
        _add_bsdf(bsdf, nested, name=name)


def write_mitsuba(material: dict[str, Any], path: str | Path, notes: list[str],
                  bsdf_id: str = "gonio_sample") -> Path:
    """Write `<scene version=...><bsdf type=... id=...>` with typed parameters and notes."""
    path = Path(path)
    scene = ET.Element("scene", version=SCENE_VERSION)
    for note in notes:  # "--" may not appear inside an XML comment
        scene.append(ET.Comment(f" {note.replace('--', '- -')} "))
    _add_bsdf(scene, material, id=bsdf_id)
    ET.indent(scene)
    path.write_text(ET.tostring(scene, encoding="unicode") + "\n")
    return path


def write_plugin_beside(path: str | Path) -> Path:
    """Copy the plugin (calibration.exports.mitsuba_plugin) to PLUGIN_FILE beside `path`."""
    plugin = Path(path).with_name(PLUGIN_FILE)
    shutil.copyfile(Path(__file__).with_name("mitsuba_plugin.py"), plugin)
    return plugin
