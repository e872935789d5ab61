"""Mitsuba 3 material from a fit: a `roughdielectric` (or `roughconductor`) BSDF in a scene
fragment, with the fitted distribution, alpha (or alpha_u / alpha_v) and index.

Mitsuba 3 knows Beckmann and GGX only: a Phong fit is written as the Beckmann distribution of
the same alpha (Walter's mapping makes them agree for narrow lobes) and says so in a comment.
Mitsuba's masking is the separable Smith form; a fit that preferred the height-correlated form
is noted likewise. A fitted scale factor goes to specular_reflectance / specular_transmittance.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

SCENE_VERSION = "3.0.0"


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


def write_mitsuba(material: dict[str, Any], path: str | Path, notes: list[str],
                  bsdf_id: str = "gonio_sample") -> Path:
    """Write `<scene version=...><bsdf type=... id=...>` with typed parameters and notes."""
    path = Path(path)
    scene = ET.Element("scene", version=SCENE_VERSION)
    for note in notes:  # "--" may not appear inside an XML comment
        scene.append(ET.Comment(f" {note.replace('--', '- -')} "))
    bsdf = ET.SubElement(scene, "bsdf", type=material["type"], id=bsdf_id)
    for name, value in material["params"].items():
        if isinstance(value, str):
            ET.SubElement(bsdf, "string", name=name, value=value)
        elif name in ("specular_reflectance", "specular_transmittance", "eta", "k"):
            ET.SubElement(bsdf, "rgb", name=name, value=f"{value:.9g}")
        else:
            ET.SubElement(bsdf, "float", name=name, value=f"{value:.9g}")
    ET.indent(scene)
    path.write_text(ET.tostring(scene, encoding="unicode") + "\n")
    return path
