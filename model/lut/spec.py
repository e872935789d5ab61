"""What a table is: kind, shape, storage dtype, Monte Carlo budget, seed, tiling and model.

Everything that changes a single bit of the baked table is in the spec (and is written into
the table file); the worker layout is not, because it does not change the result.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

from model.lut.axes import ETA_MAX, Axis, axes_for
from model.lut.remap import DESCRIPTION, REMAPS

FORMAT = "gonio-lut/1"  # the stored table's format, in every table file's metadata
KINDS = ("reflection", "transmission", "transmission-blur", "transmission-direction")
DTYPES = ("float16", "float32", "float64")
CHANNELS = {"reflection": ("scale", "bias"), "transmission": ("transmittance",),
            "transmission-blur": ("blur_alpha", "residual"),
            "transmission-direction": ("offset",)}
DIMENSIONS = {"reflection": 2, "transmission": 3, "transmission-blur": 3,
              "transmission-direction": 3}
#: A fixed-index transmission table's channels: T at eta and at 1 / eta (both sides of glass).
FIXED_ETA_CHANNELS = ("transmittance", "transmittance_reciprocal")


def parse_size(text: str) -> tuple[int, ...]:
    """'64x64x32' -> (64, 64, 32); each size an integer >= 2."""
    try:
        shape = tuple(int(part) for part in text.lower().split("x"))
    except ValueError:
        raise ValueError(f"size {text!r} is not like 64x64 or 64x64x32") from None
    if not all(n >= 2 for n in shape):
        raise ValueError(f"size {text!r}: every axis needs at least 2 nodes")
    return shape


@dataclass(frozen=True)
class TableSpec:
    """A split-sum table to bake: see docs/lut.md for the meaning of every field."""

    kind: str = "transmission"
    shape: tuple[int, ...] = (64, 64, 32)
    dtype: str = "float16"
    samples: int = 1024
    seed: int = 0
    tile_entries: int = 128
    distribution: str = "ggx"
    masking: str = "correlated"
    multiple_scattering: bool = False
    reflection_eta: float = 1.5
    remap: str | None = None  # N.V coordinate (lut.remap): "tir" for transmission, else "none"
    eta: float | None = None  # transmission at this one index and its reciprocal: a 2-D table

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"kind {self.kind!r} is not one of {', '.join(KINDS)}")
        if self.remap is None:
            object.__setattr__(self, "remap", "tir" if self.kind == "transmission" else "none")
        if self.remap not in REMAPS:
            raise ValueError(f"remap {self.remap!r} is not one of {', '.join(REMAPS)}")
        if self.remap != "none" and self.kind != "transmission":
            raise ValueError(f"remap {self.remap!r} is for transmission tables (the TIR edge); "
                             f"a {self.kind} table takes remap 'none'")
        if self.eta is not None and (self.kind != "transmission"
                                     or not 1 / ETA_MAX <= self.eta <= ETA_MAX
                                     or self.eta == 1.0):
            raise ValueError(f"eta {self.eta} fixes the index of a transmission table: give a "
                             f"value in [{1 / ETA_MAX:g}, {ETA_MAX:g}] other than 1")
        if len(self.shape) != self.dimensions:
            names = " x ".join(a.name for a in axes_for(self.kind, (2,) * self.dimensions))
            raise ValueError(
                f"a {self.kind} table{' at a fixed eta' if self.eta is not None else ''} has "
                f"{self.dimensions} axes ({names}), got size {'x'.join(map(str, self.shape))}")
        if any(int(n) != n or n < 2 for n in self.shape):
            raise ValueError(f"size {self.shape}: every axis needs at least 2 nodes")
        if self.dtype not in DTYPES:
            raise ValueError(f"dtype {self.dtype!r} is not one of {', '.join(DTYPES)}")
        if self.samples < 2 or self.samples & (self.samples - 1):
            raise ValueError(f"samples must be a power of two >= 2 (Sobol points), "
                             f"got {self.samples}")
        if self.tile_entries < 1:
            raise ValueError(f"tile_entries must be >= 1, got {self.tile_entries}")
        if not 0 <= self.seed < 2**63:
            raise ValueError(f"seed must be in [0, 2^63), got {self.seed}")
        if not self.reflection_eta > 1.0:
            raise ValueError(f"reflection_eta must be > 1, got {self.reflection_eta}")
        if self.kind == "reflection" and self.multiple_scattering:
            raise ValueError("the reflection table's F0 split holds for single scattering only; "
                             "multiple scattering is available for --kind transmission")
        if self.kind in ("transmission-blur", "transmission-direction") and \
                self.multiple_scattering:
            raise ValueError(f"the {self.kind} table describes the single-scattering lobe; "
                             f"multiple scattering is available for --kind transmission")

    @property
    def dimensions(self) -> int:
        """Number of axes: the kind's, less the eta axis when the index is fixed."""
        return DIMENSIONS[self.kind] - (self.eta is not None)

    @property
    def remapped(self) -> bool:
        """True when the N.V axis holds model.lut.remap's coordinate (and every range's ends
        are nodes)."""
        return self.remap != "none"

    @property
    def axes(self) -> tuple[Axis, ...]:
        """The table's axes, in index order."""
        return axes_for(self.kind, self.shape, ends=self.remapped,
                        cos_theta=DESCRIPTION if self.remapped else None)

    @property
    def etas(self) -> tuple[float, ...] | None:
        """A fixed-index table's index for each channel (eta, 1 / eta); else None."""
        return None if self.eta is None else (self.eta, 1.0 / self.eta)

    @property
    def array_shape(self) -> tuple[int, ...]:
        """Shape of the stored array: axes in reverse (eta, alpha, N.V), then channels, so
        that in C order N.V runs fastest: the texture layout with x = N.V, y = roughness,
        z = eta, uploadable as is."""
        return (*self.shape[::-1], len(self.channels))

    @property
    def channels(self) -> tuple[str, ...]:
        """Names of the values stored per entry (the last table dimension)."""
        return CHANNELS[self.kind] if self.eta is None else FIXED_ETA_CHANNELS

    def to_dict(self) -> dict:
        """JSON-ready fields."""
        d = asdict(self)
        d["shape"] = list(self.shape)
        return d

    @classmethod
    def from_dict(cls, d: dict) -> TableSpec:
        """Inverse of to_dict (a file from before the remap has no remap field: "none")."""
        return cls(**{"remap": "none", **d, "shape": tuple(d["shape"])})
