"""Export a run's readings, one row per reading: CSV (with a commented header of the run's
record) and CF-1.8 NetCDF4 (calibration.exports.cf: one variable per field along a `reading`
dimension, the record as attributes); the record is gonio.record.run_record's."""

from __future__ import annotations

import csv
from pathlib import Path

from calibration.exports.measured import angle_text
from gonio.record import on_virtual_clock, record_lines, run_record
from gonio.store import READING_DTYPE, Run


def write_csv(run: Run, out: Path) -> Path:
    """CSV with a header row of field names; lines `# key: JSON value` before it hold the run's
    record (gonio.record.run_record). Angles (the `_deg` fields) by angle_text, other numbers
    by repr, NaN as an empty field."""
    r = run.readings()
    angle = [name.endswith("_deg") for name in READING_DTYPE.names]
    with open(out, "w", newline="") as fh:
        for line in record_lines(run_record(run)):
            fh.write(f"# {line}\n")
        writer = csv.writer(fh)
        writer.writerow(READING_DTYPE.names)
        for row in r.tolist():
            writer.writerow(["" if isinstance(v, float) and v != v else
                             (angle_text(v) if is_angle else repr(v)) if isinstance(v, float)
                             else v for v, is_angle in zip(row, angle, strict=True)])
    return out


def write_netcdf(run: Run, out: Path) -> Path:
    """CF-1.8 NetCDF4 file of the readings, dimension `reading` (calibration.exports.cf)."""
    from calibration.exports.cf import write_raw_netcdf

    return write_raw_netcdf(run.readings(), run_record(run), out, run.meta.get("t0_epoch"),
                            virtual_clock=on_virtual_clock(run.meta))
