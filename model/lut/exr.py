"""OpenEXR storage of a baked table (the ASWF OpenEXR 3.x Python bindings, the `exr` extra):
HALF channels for float16, FLOAT for float32, a 3-D table as a 2-D atlas of eta slices, and
the table's metadata in string header attributes, so a renderer's EXR loader can read it.

Atlas: the stored array (spec.array_shape, N.V fastest) viewed as rows x N.V columns, so
pixel (x, y) of a transmission table is N.V node x, roughness node y mod n_alpha and eta node
y div n_alpha (eta slices stacked top to bottom); a reflection table is one slice.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from model.lut.spec import FORMAT, TableSpec

#: EXR channel carrying each table channel (texture-style names: R, G).
EXR_CHANNELS = ("R", "G")
#: Prefix of gonio's header attributes; each holds one metadata field as a JSON string.
PREFIX = "gonio."
PIXEL_TYPES = {"float16": "HALF", "float32": "FLOAT"}


def check_exr(spec: TableSpec) -> None:
    """Raise ValueError unless spec can be written as EXR here (HALF or FLOAT, and the
    OpenEXR package installed): called before a bake, so nothing is computed in vain."""
    if spec.dtype not in PIXEL_TYPES:
        raise ValueError(f"an .exr table stores float16 (HALF) or float32 (FLOAT), "
                         f"not {spec.dtype}; use --dtype float16 or float32, or an .npz file")
    _openexr()


def _openexr():
    """The OpenEXR module, or a ValueError saying how to install it."""
    try:
        import OpenEXR
    except ImportError:
        raise ValueError("writing or reading .exr tables needs the OpenEXR package "
                         "(pip install 'gonio[exr]')") from None
    return OpenEXR


def atlas_description(spec: TableSpec) -> dict:
    """How the table sits in the image, for the header and docs/lut.md."""
    axes = spec.axes
    rows = int(np.prod([a.size for a in axes[1:]]))
    layout = (f"pixel (x, y): cos_theta node x, alpha node y % {axes[1].size}"
              + (f", eta node y // {axes[1].size} (eta slices stacked top to bottom)"
                 if len(axes) == 3 else ""))
    return {"width": axes[0].size, "height": rows, "layout": layout,
            "channels": dict(zip(EXR_CHANNELS, spec.channels, strict=False)),
            "pixel_type": PIXEL_TYPES.get(spec.dtype)}


def save_exr(spec: TableSpec, data: np.ndarray, metadata: dict, path: str | Path) -> Path:
    """Write a table (its spec, stored array and metadata, as read_exr gives them back) as a
    scanline, ZIP-compressed .exr with gonio's metadata attributes."""
    check_exr(spec)
    exr = _openexr()
    path = Path(path)
    image = np.ascontiguousarray(data).reshape(-1, spec.shape[0], len(spec.channels))
    channels = {name: np.ascontiguousarray(image[..., k])
                for k, name in enumerate(EXR_CHANNELS[: len(spec.channels)])}
    header = {"compression": exr.ZIP_COMPRESSION, "type": exr.scanlineimage}
    fields = {**metadata, "atlas": atlas_description(spec)}
    header |= {PREFIX + key: json.dumps(value) for key, value in fields.items()}
    try:
        with exr.File(header, channels) as out:
            out.write(str(path))
    except RuntimeError as exc:  # the bindings report an unwritable path this way
        raise OSError(f"{exc}") from None
    return path


def read_exr(path: str | Path) -> tuple[TableSpec, np.ndarray, dict]:
    """Read a table written by save_exr: its spec, the same array (dtype included) and its
    metadata (model.lut.table.load_table makes the Table)."""
    exr = _openexr()
    try:
        with exr.File(str(path)) as f:  # the header and channels live only while it is open
            header = dict(f.header())
            channels = {name: np.array(c.pixels) for name, c in f.channels().items()}
    except RuntimeError as exc:
        raise ValueError(f"{path}: not a readable OpenEXR file ({exc})") from None
    meta = {key[len(PREFIX):]: json.loads(value) for key, value in header.items()
            if key.startswith(PREFIX) and isinstance(value, str)}
    if meta.get("format") != FORMAT:
        raise ValueError(f"{path}: not a gonio lookup table (no {PREFIX}format = {FORMAT!r} "
                         f"attribute)")
    spec = TableSpec.from_dict(meta["spec"])
    names = EXR_CHANNELS[: len(spec.channels)]
    if set(channels) != set(names):
        raise ValueError(f"{path}: channels {sorted(channels)}, expected {list(names)}")
    data = np.stack([channels[name] for name in names], axis=-1)
    if data.dtype != np.dtype(spec.dtype) or data.size != int(np.prod(spec.array_shape)):
        raise ValueError(f"{path}: image {data.shape} {data.dtype} does not match its metadata")
    return spec, data.reshape(spec.array_shape), meta
