"""Export a run's readings, one row per reading: CSV (with a commented header of the run's
record) and NetCDF4 (one variable per field along a `reading` dimension, the record as
attributes); the record is gonio.record.run_record's."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from gonio.errors import GonioError
from gonio.record import record_attributes, record_lines, run_record
from gonio.store import READING_DTYPE, Run

UNITS = {"_deg": "degree", "_w": "W", "t_s": "s"}


def _unit(name: str) -> str:
    return next((u for suffix, u in UNITS.items() if name.endswith(suffix)), "")


def write_csv(run: Run, out: Path) -> Path:
    """CSV with a header row of field names; lines `# key: JSON value` before it hold the run's
    record (gonio.record.run_record)."""
    r = run.readings()
    with open(out, "w", newline="") as fh:
        for line in record_lines(run_record(run)):
            fh.write(f"# {line}\n")
        writer = csv.writer(fh)
        writer.writerow(READING_DTYPE.names)
        for row in r.tolist():
            writer.writerow(["" if isinstance(v, float) and v != v else
                             repr(v) if isinstance(v, float) else v for v in row])
    return out


def write_netcdf(run: Run, out: Path) -> Path:
    """NetCDF4 file: dimension `reading`, one variable per field with its unit."""
    try:
        import netCDF4
    except ImportError:
        raise GonioError("NetCDF export needs the netCDF4 package "
                         "(pip install 'gonio[netcdf]')") from None
    r = run.readings()
    with netCDF4.Dataset(out, "w", format="NETCDF4") as ds:
        ds.createDimension("reading", len(r))
        for name in READING_DTYPE.names:
            col = r[name]
            if col.dtype.kind == "O":  # text
                var = ds.createVariable(name, str, ("reading",))
                var[:] = col
            elif col.dtype.kind == "b":
                var = ds.createVariable(name, "i1", ("reading",))
                var[:] = col.astype(np.int8)
            else:
                var = ds.createVariable(name, col.dtype, ("reading",))
                var[:] = col
            if _unit(name):
                var.units = _unit(name)
        ds.setncatts(record_attributes(run_record(run)))
        ds.Conventions = "gonio run export; angles in the sample frame of docs/architecture.md"
    return out
