"""A reader of the Mitsuba 3 XML files gonio writes (calibration.exports.mitsuba), for the
tests that read them back."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

from calibration.values import CalibrationError


def read_mitsuba(path: str | Path) -> dict[str, Any]:
    """{"type", "id", "params"} of the first bsdf of a Mitsuba 3 XML file (numbers as floats)."""
    path = Path(path)
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as exc:
        raise CalibrationError(f"{path}: not valid XML ({exc})") from exc
    bsdf = root.find("bsdf") if root.tag == "scene" else root
    if bsdf is None or bsdf.tag != "bsdf":
        raise CalibrationError(f"{path}: no <bsdf> element")
    params: dict[str, Any] = {}
    for child in bsdf:
        name, value = child.get("name"), child.get("value")
        if name is None or value is None:
            continue
        params[name] = value if child.tag == "string" else float(value.split(",")[0])
    return {"type": bsdf.get("type"), "id": bsdf.get("id"), "params": params,
            "version": root.get("version")}
