"""Filter models: what an estimator sees of a problem (f, h, Jacobians, Q, R, names)."""

from quadest.models.base import FilterModel

__all__ = ["FilterModel"]
