"""The conformance kit: the checks a plugin author runs in their own test suite (``docs/plugins.md``,
"Conformance").

- :func:`check_estimator`, :func:`check_sigma_point_moments`: an estimator class against the
  Kalman filter on a linear-Gaussian model and against closed-form moments of quadratics
  (:mod:`quadest.conformance.estimators`).

Each check raises ``AssertionError`` naming the first check that fails.
"""

from quadest.conformance.estimators import (
    Quadratic,
    check_estimator,
    check_sigma_point_moments,
    linear_gaussian_problem,
    quadratic_moments,
)

__all__ = [
    "Quadratic",
    "check_estimator",
    "check_sigma_point_moments",
    "linear_gaussian_problem",
    "quadratic_moments",
]
