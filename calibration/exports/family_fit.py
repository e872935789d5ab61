"""A fit of one of the model families beside the microfacet interface (model.bsdf.families), as
the exports take it: the family's name, its parameters by name, its fixed settings and the
fitted scale; and which export formats hold which family natively (the others refuse it, naming
the formats that do; the tabulated Zemax and ASTM exports take every family).

A fit result names its family in `family` ("microfacet" where it has none: a fit file made
before the families exports as the microfacet fit it is)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from calibration.values import CalibrationError
from model.bsdf.families import FAMILY_NAMES, family_class, make_family

MICROFACET = "microfacet"
#: Formats that hold a family in a native form of their own (not a table of its values).
NATIVE_FORMATS: dict[str, tuple[str, ...]] = {
    "mitsuba": (MICROFACET, "lambert", "lambert+microfacet"),
    "abg": ("abg",),
}
#: Formats that tabulate any family's values (zemax: `--what model`, astm on a grid).
TABULATED_FORMATS = ("zemax", "astm")
#: Width (deg) of the grid's fine part about the specular direction for a family without a
#: lobe there (the diffuse families): their value changes on the scale of tens of degrees.
BROAD_WIDTH_DEG = 10.0


@dataclass(frozen=True)
class FamilyFit:
    """One family's fitted model: parameters by the names its PARAMETERS give, fixed settings
    (e.g. the coat's distribution) and the fit's scale factor (1 when not fitted)."""

    family: str
    values: Mapping[str, float]
    settings: Mapping[str, Any] = field(default_factory=dict)
    scale: float = 1.0

    def model(self):
        """The family's model.bsdf model (without the scale)."""
        return make_family(self.family, self.values, **self.settings)

    def point_model(self):
        """f(wi, wo) in 1/sr, scale included, as the tabulated exports call it."""
        model = self.model()

        def f(wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
            return self.scale * model.eval(wi, wo)

        return f

    def lobe_width_deg(self) -> float:
        """Angular width of the model's peak about the specular direction (sizes the tabulated
        grid): the coat's alpha, ABg's knee B^(1/g) as an angle, else BROAD_WIDTH_DEG."""
        if "alpha" in self.values:
            return math.degrees(float(self.values["alpha"]))
        if self.family == "abg" and self.values["g"] > 0:
            knee = math.exp(math.log(self.values["B"]) / self.values["g"])
            return max(math.degrees(math.asin(min(knee, 1.0))), 1e-3)
        return BROAD_WIDTH_DEG

    def title(self) -> str:
        """The family and its settings: `lambert+microfacet (distribution ggx)`."""
        said = ", ".join(f"{k} {v}" for k, v in self.settings.items())
        return f"{self.family} ({said})" if said else self.family

    def describe(self) -> str:
        """The family, its settings, parameters and scale in one phrase."""
        said = ", ".join([f"{k} = {v:.6g}" for k, v in self.values.items()]
                         + [f"{k} {v}" for k, v in self.settings.items()])
        scale = "" if self.scale == 1.0 else f", scale {self.scale:.6g}"
        return f"{self.family} ({said}{scale})"


def family_of(result) -> str:
    """The family a fit result names (MICROFACET where it names none)."""
    return getattr(result, "family", None) or MICROFACET


def family_fit(result) -> FamilyFit | None:
    """The FamilyFit of a fit result (calibration.fit.FitResult) of a family, None for a
    microfacet fit: its parameters by name, fitted and held (the scale apart), its settings
    from the result's `settings` mapping or its attributes of the settings' names."""
    family = family_of(result)
    if family == MICROFACET:
        return None
    cls = family_class(family)
    names = {p.name for p in cls.PARAMETERS}
    fitted = dict(zip(result.names, result.values, strict=True))
    held = getattr(result, "fixed", None) or {}  # parameters the fit held (a coat's eta)
    values = {n: float(v) for n, v in {**fitted, **held}.items() if n in names}
    given = getattr(result, "settings", None) or {}
    settings = {name: given.get(name, getattr(result, name, None)) for name in cls.SETTINGS}
    scale = fitted.get("scale", 1.0)
    return FamilyFit(family, values, {k: v for k, v in settings.items() if v}, float(scale))


def formats_for(family: str) -> list[str]:
    """The export formats that take `family`: those that hold it natively, then the tabulated."""
    return [fmt for fmt, families in NATIVE_FORMATS.items() if family in families] + list(
        TABULATED_FORMATS)


def check_family(fmt: str, family: str) -> None:
    """Nothing if `fmt` holds `family` natively; else a CalibrationError naming the family and
    the formats that take it."""
    if family in NATIVE_FORMATS.get(fmt, ()):
        return
    if family != MICROFACET and family not in FAMILY_NAMES:
        raise CalibrationError(f"export: the fit's family {family!r} is none of gonio's "
                               f"({', '.join((MICROFACET, *FAMILY_NAMES))})")
    raise CalibrationError(
        f"export: --format {fmt} has no form of the {family} family; a {family} fit exports "
        f"as --format {' or '.join(formats_for(family))} (zemax and astm tabulate it)")
