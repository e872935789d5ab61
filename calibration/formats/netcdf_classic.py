"""The header of a classic NetCDF file (CDF-1, CDF-2 and CDF-5, as the NetCDF Classic Format
Specification lays them out), walked before the netCDF library opens the file: every count it
declares must fit in the bytes that follow, every dimension a variable names must exist, every
type must be known and every variable's values must lie within the file, since a classic file
stores each value it declares. The library trusts its header: a count of 65535 dimensions in
a variable of a 300-byte file crashed it."""

from __future__ import annotations

import struct
from math import prod
from pathlib import Path

from calibration.values import CalibrationError

#: The bytes of one value of each external type (NC_BYTE .. NC_DOUBLE; CDF-5 adds NC_UBYTE ..
#: NC_UINT64).
TYPE_BYTES = {1: 1, 2: 1, 3: 2, 4: 4, 5: 4, 6: 8, 7: 1, 8: 2, 9: 4, 10: 8, 11: 8}
NC_DIMENSION, NC_VARIABLE, NC_ATTRIBUTE = 10, 11, 12
STREAMING = 0xFFFFFFFF  # numrecs of a CDF-1 or CDF-2 file still being written


class _Header:
    """A cursor over a classic header: fixed-size integers, counts that must fit in what
    follows, names, and one error naming the file and the byte where the header is wrong."""

    def __init__(self, path: Path, data: bytes):
        self.path, self.data, self.pos = path, data, 4
        self.version = data[3]
        self.wide = self.version == 5  # CDF-5: 64-bit counts, lengths and offsets

    def fail(self, message: str) -> CalibrationError:
        return CalibrationError(f"{self.path}: damaged NetCDF header at byte {self.pos}: "
                                f"{message}")

    def _int(self, fmt: str) -> int:
        size = struct.calcsize(fmt)
        if self.pos + size > len(self.data):
            raise self.fail("the file ends inside the header")
        (value,) = struct.unpack_from(fmt, self.data, self.pos)
        self.pos += size
        return value

    def int32(self) -> int:
        return self._int(">i")

    def non_neg(self) -> int:
        """A count, length or id: 64 bits in CDF-5, else 32."""
        value = self._int(">q" if self.wide else ">i")
        if value < 0:
            raise self.fail(f"negative count {value}")
        return value

    def offset(self) -> int:
        return self._int(">i" if self.version == 1 else ">q")

    def count(self, least_bytes: int, what: str) -> int:
        """A count of items of at least least_bytes each, which must fit in the bytes left."""
        n = self.non_neg()
        if n * least_bytes > len(self.data) - self.pos:
            raise self.fail(f"{n} {what} declared, more than the file's {len(self.data)} bytes "
                            "hold")
        return n

    def skip(self, nbytes: int) -> None:
        """Move past nbytes and their padding to 4 bytes (they must be in the file)."""
        padded = nbytes + (-nbytes % 4)
        if self.pos + padded > len(self.data):
            raise self.fail("the file ends inside the header")
        self.pos += padded

    def name(self) -> str:
        n = self.count(1, "name bytes")
        start = self.pos
        self.skip(n)
        try:
            return self.data[start:start + n].decode("utf-8")
        except UnicodeDecodeError:
            raise self.fail("a name that is not UTF-8") from None

    def list_of(self, tag: int, least_bytes: int, what: str) -> int:
        """The item count of a dim, attribute or variable list (ABSENT: 0)."""
        found = self.int32()
        n = self.count(least_bytes, what)
        if found not in (0, tag) or (found == 0 and n):
            raise self.fail(f"expected the {what} list")
        return n

    def nc_type(self) -> int:
        kind = self.int32()
        if kind not in TYPE_BYTES or (kind > 6 and not self.wide):
            raise self.fail(f"unknown type {kind}")
        return kind

    def attributes(self) -> None:
        for _ in range(self.list_of(NC_ATTRIBUTE, 12, "attributes")):
            self.name()
            size = TYPE_BYTES[self.nc_type()]
            self.skip(self.count(size, "attribute values") * size)


def check_classic_header(path: Path, data: bytes) -> None:
    """Refuse, with one CalibrationError naming the file, a classic NetCDF file (`data`, its
    bytes) whose header is malformed or declares values the file does not hold."""
    if data[:3] != b"CDF" or len(data) < 4 or data[3] not in (1, 2, 5):
        raise CalibrationError(f"{path}: not a classic NetCDF file (CDF-1, CDF-2 or CDF-5)")
    h = _Header(path, data)
    numrecs = h._int(">q" if h.wide else ">I")
    lengths = []
    for _ in range(h.list_of(NC_DIMENSION, 8, "dimensions")):
        h.name()
        lengths.append(h.non_neg())
    h.attributes()
    for _ in range(h.list_of(NC_VARIABLE, 24, "variables")):
        name = h.name()
        dims = [h.non_neg() for _ in range(h.count(4, "dimensions of a variable"))]
        if any(d >= len(lengths) for d in dims):
            raise h.fail(f"variable {name} names a dimension the file does not declare")
        h.attributes()
        size = TYPE_BYTES[h.nc_type()]
        h._int(">Q" if h.wide else ">I")  # vsize: 2**32 - 1 for a large variable; unused
        begin = h.offset()
        shape = [lengths[d] for d in dims]
        record = bool(dims) and shape[0] == 0
        if record and numrecs == STREAMING and not h.wide:
            continue
        values = prod(shape[1:]) * numrecs if record else prod(shape)
        if begin < 0 or begin + values * size > len(data):
            raise CalibrationError(f"{path}: variable {name} declares {values * size} bytes of "
                                   f"data at byte {begin}, the file holds {len(data)}")
