"""Every export of a run, in one place: what was measured (`raw` readings: CSV, NetCDF, and
Bluesky event-model documents as JSON lines; `reduced` BSDF with its uncertainties: CSV, NetCDF,
Zemax with model fill, ASTM E1392) and the fitted `model` (Zemax, ASTM on a grid, Mitsuba 3),
each carrying the run's record (gonio.record.run_record). The formats, their suffixes, defaults
and writers are declared in calibration.formats.

`write(run_dir, fmt, out_path, request)` is what `gonio export --format FMT` calls."""

from __future__ import annotations

from pathlib import Path

from calibration.exports.request import ExportRequest
from calibration.formats import FORMATS, formats_with_suffix
from calibration.values import CalibrationError


def write(run_dir: str | Path, fmt: str, out_path: str | Path,
          request: ExportRequest | None = None) -> tuple[list[Path], list[str]]:
    """Write a run as `fmt` (a name in calibration.formats.FORMATS) and return (every file
    written, notes for the user). Defaults: each format's default_what; csv and netcdf write
    the reduced data where the run can be reduced (else its raw readings, with a note saying
    why; not when a reduction option or --what asks for the reduced data), zemax and astm the
    reduced data (the model filling only where there is no data), mitsuba the model. Zemax and
    ASTM write one file per measured side: the BTDF at out_path (the BRDF if only reflection
    was measured), the other beside it as <stem>-BRDF<suffix>. out_path must end in one of the
    format's suffixes (checked before any work)."""
    request = request or ExportRequest()
    what = checked_what(fmt, request.what, Path(out_path))
    file_format = FORMATS[fmt]
    # The writers load on use: the CLI reads the formats when it starts, and the reduction and
    # the fit bring in scipy.
    from calibration.exports.run_files import write_run

    asked_to_reduce = (request.what is not None or request.calibration is not None
                       or request.shot_noise_w is not None or request.subtract_signature)
    return write_run(run_dir, fmt, what, Path(out_path), request,
                     fallback=not asked_to_reduce and file_format.raw_fallback)


def checked_what(fmt: str, what: str | None, out_path: Path) -> str:
    """What an export of `fmt` writes (`what`, else the format's default), once the format,
    what and out_path's suffix are checked (CalibrationError naming the first wrong one): the
    checks an export makes before reading the run."""
    if fmt not in FORMATS:
        raise CalibrationError(f"export: format must be one of {', '.join(FORMATS)}, got "
                               f"{fmt!r}")
    file_format = FORMATS[fmt]
    what = what or file_format.default_what
    if what not in file_format.whats:
        raise CalibrationError(f"export: --what {what} is not written as {fmt} (it takes "
                               f"{' or '.join(file_format.whats)})")
    check_suffix(fmt, out_path)
    return what


def check_suffix(fmt: str, out_path: Path) -> None:
    """A CalibrationError unless out_path ends in one of the format's suffixes (naming the
    format it would suit)."""
    suffix = out_path.suffix.lower()
    suffixes = FORMATS[fmt].suffixes
    if suffix in suffixes:
        return
    others = [other.name for other in formats_with_suffix(suffix)]
    said = f"ends in {suffix}" if suffix else "has no suffix"
    hint = f", which is --format {' or '.join(others)}'s" if others else ""
    raise CalibrationError(f"export: --out {out_path} {said}{hint}; --format {fmt} writes "
                           f"{' or '.join(suffixes)}")
