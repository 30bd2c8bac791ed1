"""Estimators behind one interface (docs/plugins.md): the batched thesis SR-UKF, a batched
cubature filter, and the filterpy baselines. Every estimator module in this package is found by
the registry; installed packages add more through the ``quadest.estimators`` entry points."""

from quadest.estimators.base import CAPABILITIES, Estimator, PerRunAdapter, SingleRunEstimator

__all__ = ["CAPABILITIES", "Estimator", "PerRunAdapter", "SingleRunEstimator"]
