"""Every export of a run, in one place: its readings (`raw`: CSV, NetCDF; `bluesky`: event-model
documents as JSON lines) and its fitted model (`model`: Zemax tabular BSDF, Mitsuba 3
material), each carrying the run's record (gonio.record.run_record).

`write(run_dir, fmt, out_path)` is what `gonio export --format FMT` calls."""

from __future__ import annotations

from pathlib import Path

from calibration.values import CalibrationError

RAW_FORMATS = ("csv", "netcdf", "bluesky")
MODEL_FORMATS = ("zemax", "mitsuba")
FORMATS = RAW_FORMATS + MODEL_FORMATS


def write(run_dir: str | Path, fmt: str, out_path: str | Path) -> list[Path]:
    """Write a run as `fmt` (one of FORMATS) and return every file written: a raw export one
    row per reading; a model export reduces and fits the run first (zemax with both sides
    measured writes the main file, then the other side's)."""
    # The writers load on use: the CLI reads FORMATS here when it starts, and a model export
    # brings in the reduction and the fit (scipy).
    if fmt in RAW_FORMATS:
        from calibration.exports.bluesky import write_jsonl
        from calibration.exports.raw import write_csv, write_netcdf
        from gonio.store import open_run

        writer = {"csv": write_csv, "netcdf": write_netcdf, "bluesky": write_jsonl}[fmt]
        return [writer(open_run(run_dir), Path(out_path))]
    if fmt in MODEL_FORMATS:
        from calibration.exports.model import write_model

        return write_model(run_dir, fmt, out_path)
    raise CalibrationError(f"export: format must be one of {', '.join(FORMATS)}, got {fmt!r}")
