"""What is measured: the plan's [sample] table (id, kind, nominal index, lit side, the
calibration it is a reference for, its shape and dimensions, notes).

Reduction takes the sample's kind, index and lit side from here (never from the emulator's
[sim]); every run's record carries the whole block, as the standards ask.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

from gonio.errors import PlanError
from gonio.fields import REQUIRED, Fields, stored_table

#: Opaque reflectors: reduction takes reflection only from them (the exit view's factor 1;
#: model.optics.exit_face.OPAQUE_KINDS names the same). A matte or painted panel is "diffuse"
#: or "coated" (a clear coat over a diffuse base), a reflectance standard "reference".
OPAQUE_KINDS = ("conductor", "diffuse", "coated", "reference")
#: Sample kinds as the bench knows them (sim.bench.sample.KINDS names the same).
KINDS = ("hemisphere", "slab", *OPAQUE_KINDS)
#: Kinds without a meaningful refractive index: [sample] eta is optional for them.
WITHOUT_INDEX = ("diffuse", "reference")
#: Which side the light comes from: the rough face's air side, or through the hemisphere.
LIT_FROM = ("air", "hemisphere")
#: What a reference sample is for: "angles", a smooth or mirror sample whose microfacet model
#: the angle-offset fit uses (calibration.angles); "detector", a diffuse sample whose lobe links
#: the detector's ranges. `gonio calibrate build` fits angle offsets only from an "angles" one.
REFERENCES = ("angles", "detector")
#: The sample dimensions [sample] may state, each as `<name>_mm`.
DIMENSIONS = ("diameter", "length", "width", "thickness")
#: Nominal indices gonio reduces and fits (glasses, and a conductor's real part).
ETA_RANGE = (0.01, 10.0)


@dataclass(frozen=True)
class SampleInfo:
    """[sample]: `eta` is the glass index (a conductor's real part, with `k` its extinction; a
    coat's index), None for a diffuse or reference sample that states none;
    `azimuth_reference` says what the sample azimuth 0 is lined up with; `reference` what
    calibration the sample is a reference for (REFERENCES), empty for a sample measured."""

    id: str
    kind: str
    eta: float | None
    k: float = 0.0
    lit_from: str = "air"
    description: str = ""
    reference: str = ""
    azimuth_reference: str = ""
    operator: str = ""
    notes: str = ""
    shape: str = ""
    diameter_mm: float | None = None
    length_mm: float | None = None
    width_mm: float | None = None
    thickness_mm: float | None = None

    @property
    def dimensions_mm(self) -> dict[str, float]:
        """The dimensions stated, by name (diameter, length, width, thickness), in mm."""
        return {name: value for name in DIMENSIONS
                if (value := getattr(self, f"{name}_mm")) is not None}

    def to_json(self) -> dict[str, Any]:
        """The block as stored in meta.json and exports."""
        return asdict(self)


def parse_sample(f: Fields) -> SampleInfo:
    """Validate a [sample] table: id and kind are required, and eta for every kind but those
    WITHOUT_INDEX (a diffuse or reference panel has no index to state)."""
    sample_id = f.string("id")
    if not sample_id.strip():
        raise f.fail("id", "must not be empty")
    kind = f.string("kind", choices=KINDS)
    sample = SampleInfo(
        id=sample_id,
        kind=kind,
        eta=f.number("eta", None if kind in WITHOUT_INDEX else REQUIRED, low=ETA_RANGE[0],
                     high=ETA_RANGE[1]),
        k=f.number("k", 0.0, low=0.0, high=20.0),
        lit_from=f.string("lit_from", "air", choices=LIT_FROM),
        description=f.string("description", ""),
        reference=f.string("reference", "", choices=REFERENCES),
        azimuth_reference=f.string("azimuth_reference", ""),
        operator=f.string("operator", ""),
        notes=f.string("notes", ""),
        shape=f.string("shape", ""),
        **{f"{name}_mm": f.number(f"{name}_mm", None, low=0.0, high=10_000.0, low_open=True)
           for name in DIMENSIONS},
    )
    f.done()
    if sample.lit_from == "hemisphere" and sample.kind != "hemisphere":
        raise f.fail("lit_from", f'"hemisphere" needs kind = "hemisphere", not {sample.kind!r}')
    if sample.k != 0.0 and sample.kind != "conductor":
        raise f.fail("k", f'the extinction applies to kind = "conductor" only, not '
                     f"{sample.kind!r}")
    return sample


def sample_of_plan(plan: dict[str, Any], where: str = "plan") -> SampleInfo | None:
    """The [sample] of a stored (raw) plan, or None if it has none."""
    return stored_table(plan, "sample", where, PlanError, parse_sample)
