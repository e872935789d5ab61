"""The model's estimator for each table kind: the albedo tables' ModelEstimator, the blur and
direction tables' LobeEstimator."""

from __future__ import annotations

from model.lut.lobe import QUANTITIES, LobeEstimator
from model.lut.model import ModelEstimator
from model.lut.spec import TableSpec


def estimator_for(spec: TableSpec) -> ModelEstimator:
    """The estimator that bakes (and validates) a table of spec from gonio's model."""
    if spec.kind in QUANTITIES:
        return LobeEstimator.for_spec(spec)
    return ModelEstimator.for_spec(spec)
