"""model.bsdf's public names under their old home, for one release: `from sim.bsdf import
RoughDielectric` gives model.bsdf's own class, with a DeprecationWarning naming the new home."""

from __future__ import annotations

import warnings

import model.bsdf

__all__ = model.bsdf.__all__


def __getattr__(name: str):
    """model.bsdf's `name`, with a warning that sim.bsdf is going."""
    if name not in __all__:
        raise AttributeError(f"module 'sim.bsdf' has no attribute {name!r}")
    warnings.warn(f"sim.bsdf is deprecated: import {name} from model.bsdf", DeprecationWarning,
                  stacklevel=2)
    return getattr(model.bsdf, name)
