"""Telling a measured file's format from its content: its first bytes (a binary format's
magic) or the first word of its lines (a text format's keyword)."""

from __future__ import annotations

from collections.abc import Collection
from pathlib import Path

from calibration.values import CalibrationError


def starts_with(path: Path, magic: tuple[bytes, ...]) -> bool:
    """True when the file begins with one of the magic byte strings (NetCDF 3 or 4)."""
    with open(path, "rb") as fh:
        head = fh.read(8)
    return head.startswith(magic)


def first_keyword(path: Path, keywords: Collection[str]) -> str | None:
    """The first of `keywords` that a line of a text file starts with, in the file's order;
    None if no line does."""
    try:
        with open(path, errors="replace") as fh:
            for line in fh:
                word = line.split(maxsplit=1)[:1]
                if word and word[0] in keywords:
                    return word[0]
    except OSError as exc:
        raise CalibrationError(f"{path}: {exc.strerror}") from None
    return None
