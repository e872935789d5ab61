"""Real-time split-sum lookup tables baked from the rough-dielectric model, and validated.

`TableSpec` says what to bake, `bake` computes it tile by tile (in-process or on a Dask
cluster, bitwise identical either way), `Table` stores, loads and interpolates it, and
`validate` measures its error against converged integrals. Besides the albedo tables, the
transmission-blur and transmission-direction kinds (model.lut.lobe) say which prefiltered mip
and direction a renderer fetches for rough glass; model.lut.splitsum checks the whole split sum
against brute force. See docs/lut.md.
"""

from model.lut.axes import Axis, axes_for
from model.lut.bake import bake, integrate_points
from model.lut.spec import TableSpec, parse_size
from model.lut.table import Table, load_table
from model.lut.validate import validate

__all__ = ["Axis", "Table", "TableSpec", "axes_for", "bake", "integrate_points", "load_table",
           "parse_size", "validate"]
