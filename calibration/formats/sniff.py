"""Telling a text measured file's format from its bytes: the first word of its lines (a text
format's keyword)."""

from __future__ import annotations

import io
from collections.abc import Collection


def first_keyword(data: bytes, keywords: Collection[str]) -> str | None:
    """The first of `keywords` that a line of the file's bytes starts with, in the file's
    order (lines read one at a time); None if no line does."""
    for line in io.BytesIO(data):
        word = line.split(maxsplit=1)[:1]
        if word and (text := word[0].decode("utf-8", "replace")) in keywords:
            return text
    return None
