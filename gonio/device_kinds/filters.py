"""A filter wheel's `filters` table read from its `[devices.<name>]` table: the filter at each
position, its centre wavelength and passband width, with one clear error per bad entry.

    filters = { 1 = { centre_nm = 450.0, bandwidth_nm = 10.0 }, 3 = { centre_nm = 532.0,
                bandwidth_nm = 3.0 } }

Positions are the wheel's, counted from 1; positions left out hold no filter (an empty slot, a
blank). Two filters centred on one wavelength would make the wavelength name no one position:
refused.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from gonio.fields import Fields

MAX_POSITION = 12  # the FW212C's 12-position wheel
MAX_WAVELENGTH_NM = 100_000.0

#: one filter: (position, centre_nm, bandwidth_nm)
FilterEntry = tuple[int, float, float]


def read_filters(f: Fields, key: str) -> tuple[FilterEntry, ...]:
    """The filters of the table `key` of the device table `f`, by position (a GonioError of
    f's kind naming the key and the position for the first bad entry)."""
    if not f.has(key):
        raise f.error(f"{f.where}: missing required key {key!r}")
    table = f.table[key]
    if not isinstance(table, Mapping) or not table:
        raise f.fail(key, "must be a table of positions, each {centre_nm, bandwidth_nm}, with "
                          f"at least one filter; got {table!r}")
    entries = [_filter(f, key, position, value) for position, value in table.items()]
    entries.sort()
    centres: dict[float, int] = {}
    for position, centre, _ in entries:
        if centre in centres:
            raise f.fail(f"{key}.{position}", f"centre_nm {centre:g} is also position "
                                             f"{centres[centre]}'s: a wavelength must name one "
                                             "filter")
        centres[centre] = position
    return tuple(entries)


def _filter(f: Fields, key: str, position: Any, value: Any) -> FilterEntry:
    where = f"{key}.{position}"
    if not (isinstance(position, str) and position.isdigit()
            and 1 <= int(position) <= MAX_POSITION):
        raise f.fail(where, f"a position must be a whole number 1..{MAX_POSITION}")
    entry = Fields(value, f.source, f.error, f"{f.name}.{key}.{position}")
    centre = entry.number("centre_nm", low=0.0, high=MAX_WAVELENGTH_NM, low_open=True)
    width = entry.number("bandwidth_nm", low=0.0, high=MAX_WAVELENGTH_NM, low_open=True)
    entry.done()
    return int(position), centre, width
