"""What a file format of `gonio export --format` and `--import` is (`FileFormat`): its name,
suffixes, default `--what`, its writer per `--what`, its reader and how a file of it is told
apart; the writers and the reader load when first used."""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from calibration.formats.limits import MeasuredFile
from calibration.reduced import ReducedData

#: What an export may write, in this order wherever they are listed: a run's readings, its
#: reduced BSDF with uncertainties, or the fitted model.
WHATS = ("raw", "reduced", "model")


@dataclass(frozen=True)
class ImportOptions:
    """What a file may lack: the sample's index, the relative standard uncertainty to assume
    where the file has no uncertainties, and the incidence of a CSV table of one incidence."""

    eta: float | None = None
    sigma_relative: float | None = None
    incidence_deg: float | None = None  # theta_i of a plain CSV table of one incidence


@dataclass(frozen=True, kw_only=True)
class FileFormat:
    """One format. writers: `--what` -> "module:function"; a `raw` writer takes (Run, out
    path) and returns the file written, the others take (ReducedData, out path, the run's
    record, ExportRequest, source) and return (files written, notes). reader: "module:function"
    taking (MeasuredFile, ImportOptions) to ReducedData, for a format `--import` reads.
    magic: the first bytes of a file of it, whatever its suffix; keyword: the first word of a
    line of a text file of it (calibration.formats.format_to_read)."""

    name: str
    suffixes: tuple[str, ...]  # the first is the usual one
    default_what: str
    writers: Mapping[str, str]
    reader: str | None = None
    magic: tuple[bytes, ...] = ()
    keyword: str | None = None

    @property
    def whats(self) -> tuple[str, ...]:
        """The `--what` it writes, in the order of WHATS."""
        return tuple(what for what in WHATS if what in self.writers)

    @property
    def raw_fallback(self) -> bool:
        """True if it writes a run's raw readings where the run cannot be reduced: a format
        that holds both, reduced by default."""
        return "raw" in self.writers and self.default_what != "raw"

    def writer(self, what: str) -> Callable[..., Any]:
        """The function writing `what` (one of `whats`) as this format."""
        return _loaded(self.writers[what])

    def read(self, file: MeasuredFile, options: ImportOptions) -> ReducedData:
        """A measured file (its bytes, read once) of this format as ReducedData (a format with
        a reader)."""
        return _loaded(self.reader)(file, options)


def _loaded(path: str) -> Any:
    """The function `module:name`, imported when first used: the CLI reads the formats when it
    starts, and the reduction and the fit bring in scipy."""
    module, _, name = path.partition(":")
    return getattr(importlib.import_module(module), name)
