"""Numeric replies of one exact shape: how to read one, and how precise it is.

The precision is what a setting read back can be held to: a reply with five decimals shows the
value sent rounded to five decimals, so "taken" means within half a unit of that last place.
"""

from __future__ import annotations

import math

from drivers.serial_transport import strict_number_parser


class StrictNumber:
    """A reader of numeric replies that must match `pattern` exactly (ProtocolError naming
    `expected` otherwise), showing `decimals` decimals: of the number itself, or with
    `mantissa`, of the mantissa of its scientific form (`1.234567E-06`)."""

    def __init__(self, pattern: str, expected: str, decimals: int, mantissa: bool = False):
        self.decimals, self.mantissa = int(decimals), mantissa
        self._parse = strict_number_parser(pattern, expected)

    def __call__(self, text: str) -> float:
        return self._parse(text)

    def half_unit(self, value: float) -> float:
        """Half a unit in the last place a reply shows for value."""
        exponent = math.floor(math.log10(abs(value))) if self.mantissa and value else 0
        return 0.5 * 10.0 ** (exponent - self.decimals)
