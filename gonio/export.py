"""Export a run's readings, one row per reading: CSV (with a commented header of run facts)
and NetCDF4 (one variable per field along a `reading` dimension, run facts as attributes)."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np

from gonio.errors import GonioError
from gonio.store import READING_DTYPE, Run

UNITS = {"_deg": "degree", "_w": "W", "t_s": "s"}


def _unit(name: str) -> str:
    return next((u for suffix, u in UNITS.items() if name.endswith(suffix)), "")


def _facts(run: Run) -> dict[str, str]:
    meta = run.meta
    return {"run": run.path.name, "plan": str(meta.get("plan_name", "")),
            "instrument": str(meta.get("instrument_name", "")),
            "status": str(meta.get("status", "")), "reason": str(meta.get("reason", "")),
            "started_utc": str(meta.get("started_utc", "")),
            "stopped_utc": str(meta.get("stopped_utc", "")),
            "wavelength_nm": str(run.config.get("detector", {}).get("wavelength_nm", "")),
            "sim": json.dumps(meta.get("sim")), "seeds": json.dumps(meta.get("seeds", {})),
            "calibration": json.dumps(meta.get("calibration"))}


def write_csv(run: Run, out: Path) -> Path:
    """CSV with a header row of field names; lines starting with '#' hold run facts."""
    r = run.readings()
    with open(out, "w", newline="") as fh:
        for key, value in _facts(run).items():
            fh.write(f"# {key}: {value}\n")
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
            if col.dtype.kind == "U":
                var = ds.createVariable(name, str, ("reading",))
                var[:] = col.astype(object)
            elif col.dtype.kind == "b":
                var = ds.createVariable(name, "i1", ("reading",))
                var[:] = col.astype(np.int8)
            else:
                var = ds.createVariable(name, col.dtype, ("reading",))
                var[:] = col
            if _unit(name):
                var.units = _unit(name)
        for key, value in _facts(run).items():
            setattr(ds, key, value)
        ds.Conventions = "gonio run export; angles in the sample frame of docs/architecture.md"
    return out
