"""Every export of a run, in one place: what was measured (`raw` readings: CSV, NetCDF, and
Bluesky event-model documents as JSON lines; `reduced` BSDF with its uncertainties: CSV, NetCDF,
Zemax with model fill, ASTM E1392) and the fitted `model` (Zemax, ASTM on a grid, Mitsuba 3),
each carrying the run's record (gonio.record.run_record).

`write(run_dir, fmt, out_path, request)` is what `gonio export --format FMT` calls."""

from __future__ import annotations

from pathlib import Path

from calibration.exports.request import ExportRequest
from calibration.values import CalibrationError

WHATS = ("raw", "reduced", "model")
ACCEPTS = {"csv": ("raw", "reduced"), "netcdf": ("raw", "reduced"), "bluesky": ("raw",),
           "zemax": ("reduced", "model"), "astm": ("reduced", "model"), "mitsuba": ("model",)}
DEFAULT_WHAT = {"csv": "reduced", "netcdf": "reduced", "bluesky": "raw", "zemax": "reduced",
                "astm": "reduced", "mitsuba": "model"}
FORMATS = tuple(ACCEPTS)
# The suffixes a format's file may have: those `--import` (calibration.imports) and the other
# tools recognise it by; the first is the usual one.
SUFFIXES = {"csv": (".csv",), "netcdf": (".nc",), "bluesky": (".jsonl",),
            "zemax": (".bsdf", ".zmx", ".txt"), "astm": (".astm", ".txt"), "mitsuba": (".xml",)}
RAW_FORMATS = ("csv", "netcdf")
MODEL_FORMATS = ("zemax", "mitsuba")


def write(run_dir: str | Path, fmt: str, out_path: str | Path,
          request: ExportRequest | None = None) -> tuple[list[Path], list[str]]:
    """Write a run as `fmt` (one of FORMATS) and return (every file written, notes for the
    user). Defaults: csv and netcdf the reduced data where the run can be reduced (else its
    raw readings, with a note saying why; not when a reduction option or --what asks for the
    reduced data), zemax and astm the reduced data (the model filling
    only where there is no data), mitsuba the model. Zemax and ASTM write one file per
    measured side: the BTDF at out_path (the BRDF if only reflection was measured), the other
    beside it as <stem>-BRDF<suffix>. out_path must end in one of the format's SUFFIXES
    (checked before any work)."""
    request = request or ExportRequest()
    if fmt not in ACCEPTS:
        raise CalibrationError(f"export: format must be one of {', '.join(FORMATS)}, got "
                               f"{fmt!r}")
    what = request.what or DEFAULT_WHAT[fmt]
    if what not in ACCEPTS[fmt]:
        raise CalibrationError(f"export: --what {what} is not written as {fmt} (it takes "
                               f"{' or '.join(ACCEPTS[fmt])})")
    check_suffix(fmt, Path(out_path))
    # The writers load on use: the CLI reads FORMATS here when it starts, and the reduction and
    # the fit bring in scipy.
    from calibration.exports.run_files import write_run

    asked_to_reduce = (request.what is not None or request.calibration is not None
                       or request.shot_noise_w is not None or request.subtract_signature)
    return write_run(run_dir, fmt, what, Path(out_path), request,
                     fallback=not asked_to_reduce and fmt in RAW_FORMATS)


def check_suffix(fmt: str, out_path: Path) -> None:
    """A CalibrationError unless out_path ends in one of the format's SUFFIXES (naming the
    format it would suit)."""
    suffix = out_path.suffix.lower()
    if suffix in SUFFIXES[fmt]:
        return
    others = [f for f, suffixes in SUFFIXES.items() if suffix in suffixes]
    said = f"ends in {suffix}" if suffix else "has no suffix"
    hint = f", which is --format {' or '.join(others)}'s" if others else ""
    raise CalibrationError(f"export: --out {out_path} {said}{hint}; --format {fmt} writes "
                           f"{' or '.join(SUFFIXES[fmt])}")
