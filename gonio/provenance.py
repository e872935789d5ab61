"""Who measured: the instrument config's [provenance] table (the lab and its address, the
contact person and the licence its data are given under).

Metrology data exchange (the BiRD universal BRDF format, ISO 19986's report) names the lab, a
contact and the terms of use; the record of every run carries this block.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

from gonio.errors import ConfigError
from gonio.fields import Fields, stored_table

#: The keys of the lab's postal address, in the order an address is written.
ADDRESS_KEYS = ("street", "building", "postal_code", "city", "country")


@dataclass(frozen=True)
class Provenance:
    """[provenance]: the lab (organisation) with its postal address, the contact person and
    e-mail, and the licence of the data (`licence_holder`: who holds the rights, the lab
    unless stated; `licence_url`: where its text is, "" when not stated)."""

    lab: str
    contact: str
    email: str
    street: str
    building: str
    postal_code: str
    city: str
    country: str
    licence: str
    licence_holder: str
    licence_url: str = ""
    phone: str = ""

    def to_json(self) -> dict[str, Any]:
        """The block as stored in the record and exports."""
        return asdict(self)


def _text(f: Fields, key: str) -> str:
    """A required, non-empty string."""
    value = f.string(key)
    if not value.strip():
        raise f.fail(key, "must not be empty")
    return value


def parse_provenance(f: Fields) -> Provenance:
    """Validate a [provenance] table: every key but licence_holder, licence_url and phone is
    required (an e-mail has one @ with text on both sides)."""
    lab = _text(f, "lab")
    provenance = Provenance(
        lab=lab, contact=_text(f, "contact"), email=_text(f, "email"),
        **{key: _text(f, key) for key in ADDRESS_KEYS},
        licence=_text(f, "licence"), licence_holder=f.string("licence_holder", "") or lab,
        licence_url=f.string("licence_url", ""), phone=f.string("phone", ""),
    )
    f.done()
    user, at, domain = provenance.email.partition("@")
    if not (user and at and domain and "@" not in domain and " " not in provenance.email):
        raise f.fail("email", f"must be an e-mail address, got {provenance.email!r}")
    return provenance


def provenance_of_config(config: dict[str, Any], where: str = "config") -> Provenance | None:
    """The [provenance] of a stored (raw) instrument config, or None if it has none."""
    return stored_table(config, "provenance", where, ConfigError, parse_provenance)
