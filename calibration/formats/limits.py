"""How much a measured file that `--import` reads may hold, checked before anything is
allocated: its size on disk, its points and numbers, its columns, and a text file's lines, so
that a file declaring or holding more is one error naming it (never an exhausted memory)."""

from __future__ import annotations

import io
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

from calibration.values import CalibrationError
from drivers.user_file import read_user_file

#: The most points (samples of the BSDF) an import holds: a few full hemispheres at 1 degree,
#: and what the fit takes within the memory a workstation can spare.
MAX_POINTS = 200_000
#: The most columns (or variables) an import reads.
MAX_COLUMNS = 64
#: The largest file an import opens, and a text file's most lines and longest line.
MAX_FILE_BYTES = 64 * 2**20
MAX_LINES = 2 * MAX_POINTS
MAX_LINE_CHARS = 2**20


def check_count(path: Path, count: int, what: str, limit: int) -> None:
    """One error naming the file if `count` of `what` ("points", "columns") is over `limit`,
    before they are read."""
    if count > limit:
        raise CalibrationError(f"{path}: {count} {what}; an import holds at most {limit}")


@dataclass(frozen=True)
class MeasuredFile:
    """A measured file's name and its bytes, read once: its format is told from these bytes
    and its reader reads them, so nothing opens the path again after the checks (a file put
    in its place meanwhile is never read)."""

    path: Path
    data: bytes


def measured_file(source: str | Path | MeasuredFile) -> MeasuredFile:
    """`source` itself when it is a MeasuredFile, else the file at that path read whole: a
    regular file of at most MAX_FILE_BYTES (drivers.user_file: a FIFO or a device is refused
    without blocking)."""
    if isinstance(source, MeasuredFile):
        return source
    path = Path(source)
    return MeasuredFile(path, read_user_file(path, "measured file", MAX_FILE_BYTES,
                                             CalibrationError))


def text_lines(file: MeasuredFile) -> Iterator[tuple[int, str]]:
    """The lines of a measured text file, numbered from 1, without their line ends, decoded
    one at a time: one error naming the file (and line) if it is not UTF-8 text, has more than
    MAX_LINES lines or a line longer than MAX_LINE_CHARS."""
    text = io.TextIOWrapper(io.BytesIO(file.data), encoding="utf-8", newline=None)
    number = 0
    try:
        for number, line in enumerate(text, 1):
            check_count(file.path, number, "lines or more", MAX_LINES)
            if len(line) > MAX_LINE_CHARS:
                raise CalibrationError(f"{file.path}:{number}: line longer than "
                                       f"{MAX_LINE_CHARS} characters")
            yield number, line.rstrip("\n")
    except UnicodeDecodeError:
        raise CalibrationError(f"{file.path}:{number + 1}: not UTF-8 text") from None
