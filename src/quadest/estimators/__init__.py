"""Estimators behind one interface: the batched thesis SR-UKF and the filterpy baselines."""

from quadest.estimators.base import Estimator, PerRunAdapter, SingleRunEstimator
from quadest.estimators.registry import build_estimator, builtin_estimators

__all__ = ["Estimator", "PerRunAdapter", "SingleRunEstimator", "build_estimator", "builtin_estimators"]
