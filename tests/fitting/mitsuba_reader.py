"""A reader of the Mitsuba 3 XML files gonio writes (calibration.exports.mitsuba), for the
tests that read them back."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

from calibration.values import CalibrationError


def read_mitsuba(path: str | Path) -> dict[str, Any]:
    """{"type", "id", "params", "nested", "version"} of the first bsdf of a Mitsuba 3 XML file
    (numbers as floats; nested: its nested bsdfs by name, each {"type", "params"})."""
    path = Path(path)
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as exc:
        raise CalibrationError(f"{path}: not valid XML ({exc})") from exc
    bsdf = root.find("bsdf") if root.tag == "scene" else root
    if bsdf is None or bsdf.tag != "bsdf":
        raise CalibrationError(f"{path}: no <bsdf> element")
    return {"type": bsdf.get("type"), "id": bsdf.get("id"), "params": _params(bsdf),
            "nested": {n.get("name"): {"type": n.get("type"), "params": _params(n)}
                       for n in bsdf.findall("bsdf")},
            "version": root.get("version")}


def _params(bsdf: ET.Element) -> dict[str, Any]:
    """The typed parameters of one bsdf element (numbers as floats)."""
    params: dict[str, Any] = {}
    for child in bsdf:
        name, value = child.get("name"), child.get("value")
        if name is None or value is None:
            continue
        params[name] = value if child.tag == "string" else float(value.split(",")[0])
    return params
