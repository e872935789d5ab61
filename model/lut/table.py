"""A baked table: values in the stored dtype, its spec and model, storage (.npz, or .exr
through model.lut.exr) and lookups.

Lookups interpolate multilinearly in texture coordinates with clamp-to-edge, exactly what a
GPU's linear sampler does with the same array uploaded as a texture.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from model.lut import remap
from model.lut.axes import NODES
from model.lut.exr import check_exr, read_exr, save_exr
from model.lut.spec import FORMAT, TableSpec

DEFINITIONS = {
    "reflection": {
        "scale": "integral over the reflected hemisphere of (f_r / F) * (1 - (1 - v.h)^5) * "
                 "|cos o| d o; albedo ~= F0 * scale + bias (Schlick split, single scattering)",
        "bias": "integral over the reflected hemisphere of (f_r / F) * (1 - v.h)^5 * |cos o| d o",
    },
    "transmission": {
        "transmittance": "integral over the transmitted hemisphere of f_t(v, o) * |cos o| d o "
                         "(radiance BTDF, eta_o^2 factor included, so values may exceed 1)",
    },
    "transmission-blur": {
        "blur_alpha": "GGX alpha of the split-sum reflection prefilter kernel (N = V = R, "
                      "N.L weighted) whose mean cosine about its axis equals the transmitted "
                      "lobe's |E[l]| (l weighted by f_t(l, v) |cos l|); at most 4",
        "residual": "E[1 - (l.m)^2] of the lobe about its mean direction m over the same for "
                    "the matched kernel, minus 1 (0: second moments agree too)",
    },
    "transmission-direction": {
        "offset": "polar angle (from -N, radians) of the transmitted lobe's mean direction "
                  "E[l] / |E[l]| minus that of the ideal refraction (pi/2 under TIR); "
                  "positive: away from the normal",
    },
}


def definitions(spec: TableSpec) -> dict:
    """What each stored channel of a table of spec holds (its metadata's `definitions`)."""
    base = DEFINITIONS[spec.kind]
    if spec.kind != "transmission":
        return base
    stored = base["transmittance"]
    if spec.remapped:
        stored = (f"eta^2 times the {stored}, i.e. the directional albedo E(v) (at most 1); "
                  f"divide by eta^2 for T (Table.lookup does)")
    if spec.etas is None:
        return {"transmittance": stored}
    return {name: f"at eta = {eta:g}: {stored}"
            for name, eta in zip(spec.channels, spec.etas, strict=True)}


@dataclass
class Table:
    """Baked values `data` (spec.array_shape: reversed axes, channels) in spec.dtype, with
    how they were made."""

    spec: TableSpec
    data: np.ndarray
    bake_seconds: float = float("nan")
    model: str = ""
    validation: dict | None = None

    def metadata(self) -> dict:
        """Everything needed to read and trust the table, as JSON-ready values."""
        return {
            "format": FORMAT,
            "kind": self.spec.kind,
            "channels": list(self.spec.channels),
            "definitions": definitions(self.spec),
            "axes": [{"name": a.name, "size": a.size, "parameterisation": a.parameterisation,
                      "nodes": NODES[a.ends],
                      "first": float(a.values()[0]), "last": float(a.values()[-1])}
                     for a in self.spec.axes],
            "index_order": [a.name for a in self.spec.axes[::-1]] + ["channel"],
            "spec": self.spec.to_dict(),
            "model": self.model,
            "bake_seconds": self.bake_seconds,
            "validation": self.validation,
        }

    def save(self, path: str | Path) -> Path:
        """Write an .npz: `table`, one `axis_<name>` array of node values per axis and a
        JSON `metadata` string (readable with numpy.load(allow_pickle=False)); or, for a
        path ending in .exr, an OpenEXR image (model.lut.exr). Any other ending: ValueError."""
        path = Path(path)
        check_storable(self.spec, path)
        if is_exr(path):
            return save_exr(self.spec, self.data, self.metadata(), path)
        axes = {f"axis_{a.name}": a.values() for a in self.spec.axes}
        with open(path, "wb") as fh:
            np.savez(fh, table=self.data, metadata=np.array(json.dumps(self.metadata())),
                     **axes)
        return path

    def lookup(self, *params: np.ndarray) -> np.ndarray:
        """Interpolated channels (..., channels) at parameter values (cos_theta, alpha[, eta]);
        a fixed-index table takes (cos_theta, alpha) and gives each channel at its own eta."""
        axes = self.spec.axes
        if len(params) != len(axes):
            raise ValueError(f"a {self.spec.kind} table takes {len(axes)} parameters "
                             f"({', '.join(a.name for a in axes)}), got {len(params)}")
        arrays = np.broadcast_arrays(*params)
        data = self.data.astype(np.float64)
        if self.spec.etas is None:
            stored = interpolate(data, texture_coords(self.spec, *arrays)[::-1])
            if self.spec.kind != "transmission":
                return stored
            return stored / remap.albedo_factor(self.spec.remapped, arrays[2])[..., None]
        return np.concatenate([interpolate(data[..., c:c + 1],
                                           texture_coords(self.spec, *arrays, eta)[::-1])
                               / remap.albedo_factor(self.spec.remapped, eta)
                               for c, eta in enumerate(self.spec.etas)], axis=-1)


def texture_coords(spec: TableSpec, mu: np.ndarray, alpha: np.ndarray,
                   eta: np.ndarray | float | None = None) -> list[np.ndarray]:
    """Texture coordinate on each axis of spec at (N.V, alpha[, eta]) (eta is given apart for
    a fixed-index table's channel, and is not an axis of it): what a shader computes."""
    axes = spec.axes
    params = np.broadcast_arrays(mu, alpha, *(() if eta is None else (eta,)))
    coords = [a.to_coord(p) for a, p in zip(axes, params, strict=False)]
    if spec.remapped:
        coords[0] = remap.nv_coord(params[0], params[1], params[2], axes[0].size)
    return coords


def interpolate(data: np.ndarray, coords: list[np.ndarray]) -> np.ndarray:
    """Multilinear interpolation of data (n_1, ..., n_d, channels) at texture coordinates
    (each (...,)) with texel-centre nodes and clamp-to-edge."""
    shape = np.shape(coords[0])
    result = np.zeros(shape + data.shape[-1:])
    lows, fracs = [], []
    for t, n in zip(coords, data.shape[:-1], strict=True):
        x = np.clip(np.asarray(t, dtype=np.float64) * n - 0.5, 0.0, n - 1.0)
        low = np.minimum(np.floor(x).astype(np.intp), n - 2)
        lows.append(low)
        fracs.append(x - low)
    for corner in np.ndindex(*(2,) * len(coords)):
        weight = np.ones(shape)
        index = []
        for bit, low, frac in zip(corner, lows, fracs, strict=True):
            weight = weight * (frac if bit else 1.0 - frac)
            index.append(low + bit)
        result += weight[..., None] * data[tuple(index)]
    return result


def is_exr(path: str | Path) -> bool:
    """True when a table path names an OpenEXR file (suffix .exr, any case)."""
    return Path(path).suffix.lower() == ".exr"


#: File name endings a table is written as: NumPy's .npz, or OpenEXR.
SUFFIXES = (".npz", ".exr")


def check_storable(spec: TableSpec, path: str | Path) -> None:
    """Raise ValueError now if path names no format a table is written as (.npz or .exr, any
    case), or one that cannot hold a table of spec."""
    suffix = Path(path).suffix
    if suffix.lower() not in SUFFIXES:
        instead = f" instead of {suffix!r}" if suffix else ""
        raise ValueError(f"{path}: a table is written as .npz (NumPy) or .exr (OpenEXR): give "
                         f"the file one of those extensions{instead}")
    if is_exr(path):
        check_exr(spec)


def load_table(path: str | Path) -> Table:
    """Read a table written by Table.save (.npz, or .exr); a file that is not one is a clear
    ValueError."""
    spec, data, meta = read_exr(path) if is_exr(path) else _read_npz(path)
    return Table(spec=spec, data=data, bake_seconds=meta["bake_seconds"], model=meta["model"],
                 validation=meta.get("validation"))


def _read_npz(path: str | Path) -> tuple[TableSpec, np.ndarray, dict]:
    """The spec, stored array and metadata of an .npz table, checked against each other."""
    try:
        with np.load(path, allow_pickle=False) as f:
            meta = json.loads(str(f["metadata"]))
            data = f["table"]
    except (OSError, KeyError, ValueError) as exc:
        raise ValueError(f"{path}: not a gonio lookup table ({exc})") from None
    if meta.get("format") != FORMAT:
        raise ValueError(f"{path}: format {meta.get('format')!r}, expected {FORMAT!r}")
    spec = TableSpec.from_dict(meta["spec"])
    if data.shape != spec.array_shape or data.dtype != np.dtype(spec.dtype):
        raise ValueError(f"{path}: table {data.shape} {data.dtype} does not match its metadata")
    return spec, data, meta
