"""[sim.sample] of a sample modelled by a family beside the microfacet interface: `family` and
the family's truth by the parameter names a fit reports (`rho`, `sigma`, `alpha`, `eta`, `A`,
`B`, `g`) and its fixed settings (`distribution`, `masking`, `variant`), checked here and built
with model.bsdf.families.make_family; every bad field is one SimConfigError naming it."""

from __future__ import annotations

from collections.abc import Mapping

from model.bsdf.families import family_class
from model.optics.exit_face import OPAQUE_KINDS
from sim.bench.family_sample import LOBE_WIDTHS
from sim.bench.sample import MICROFACET
from sim.devices.photodiode import SimConfigError

#: What [sim.sample] family may name: the interface, or a family the bench emulates.
FAMILY_CHOICES = (MICROFACET, *LOBE_WIDTHS)
#: The kinds the microfacet interface emulates (the others are a family's).
INTERFACE_KINDS = ("hemisphere", "slab", "conductor")
#: Keys that only the microfacet interface reads (a family sample states none of them).
MICROFACET_KEYS = ("k", "multiple_scattering", "diffraction", "rms_height_nm",
                   "correlation_length_um", "psd_exponent", "ms_walks",
                   "single_scattering_alpha", "single_scattering_alpha_u")
#: Keys of the interface that a family may take by the same name (a coat's).
SHARED_KEYS = ("distribution", "alpha", "eta", "masking")


def _names(name: str) -> tuple[str, ...]:
    cls = family_class(name)
    return (*(p.name for p in cls.PARAMETERS), *cls.SETTINGS)


#: Every family's parameter and setting names that the interface does not have: [sim.sample]
#: keys of their own.
FAMILY_KEYS = tuple(dict.fromkeys(key for name in LOBE_WIDTHS for key in _names(name)
                                  if key not in SHARED_KEYS))


def family_fields(stated: Mapping, table: dict[str, object], where: str,
                  described: Mapping[str, object]) -> dict[str, object]:
    """SampleSpec's fields from a read [sim.sample] `table` (defaults filled; FAMILY_KEYS and
    `family` are taken out of it), whose own keys are `stated`; `described` holds what the
    experimenter's [sample] gives (eta: a coat's nominal index, the truth unless stated).

    A family sample needs an opaque kind and every parameter of its family, and states no key
    of another model; the microfacet interface needs an interface kind and no family key."""
    table = dict(table)
    family = table.pop("family")
    for key in FAMILY_KEYS:
        table.pop(key)
    kind = table["kind"]
    if family == MICROFACET:
        foreign = [key for key in FAMILY_KEYS if key in stated]
        if foreign:
            raise SimConfigError(f"[{where}] {foreign[0]}: a parameter of a model family; name "
                                 f"the family (family = one of {', '.join(FAMILY_CHOICES[1:])})")
        if kind not in INTERFACE_KINDS:
            raise SimConfigError(f"[{where}] family: kind {kind!r} is emulated by a model "
                                 f"family (family = one of {', '.join(FAMILY_CHOICES[1:])}); "
                                 f"the microfacet interface is kind "
                                 f"{', '.join(INTERFACE_KINDS)}")
        return table
    if kind not in OPAQUE_KINDS:
        raise SimConfigError(f"[{where}] kind: family {family!r} only reflects: it needs kind "
                             f"{', '.join(OPAQUE_KINDS)}, not {kind!r}")
    takes = _names(family)
    model_keys = (*SHARED_KEYS, *MICROFACET_KEYS, *FAMILY_KEYS)
    foreign = [key for key in stated if key in model_keys and key not in takes]
    if foreign:
        raise SimConfigError(f"[{where}] {foreign[0]}: family {family!r} takes "
                             f"{', '.join(takes)}, not {foreign[0]}")
    cls = family_class(family)
    given = {**{k: v for k, v in described.items() if v is not None}, **stated}
    values = {}
    for p in cls.PARAMETERS:
        if p.name not in given:
            raise SimConfigError(f"[{where}] {p.name}: needed by family {family!r} (its "
                                 f"parameters: {', '.join(q.name for q in cls.PARAMETERS)})")
        values[p.name] = given[p.name]
    settings = {key: stated[key] for key in cls.SETTINGS if key in stated}
    try:
        model = cls.from_parameters(values, **settings)
    except ValueError as exc:
        raise SimConfigError(f"[{where}] family {family!r}: {exc}") from None
    truth = {**model.parameters(), **model.settings()}
    alpha = truth.get("alpha")
    table.update({key: truth[key] for key in ("distribution", "eta", "masking") if key in truth},
                 multiple_scattering=False, diffraction=False, family=family,
                 family_parameters=tuple(model.parameters().items()),
                 family_settings=tuple(model.settings().items()))
    if alpha is not None:
        table["alpha"] = (alpha, alpha)
    return table
