"""The conformance kit: the checks a plugin author runs in their own test suite (``docs/plugins.md``,
"Conformance").

- :func:`check_estimator`, :func:`check_sigma_point_moments`: an estimator class against the
  Kalman filter on a linear-Gaussian model and against closed-form moments of quadratics
  (:mod:`quadest.conformance.estimators`);
- :func:`check_sensor`: a sensor class's samples, stream isolation, availability and Jacobian
  against finite differences on the INS's manifold (:mod:`quadest.conformance.sensors`);
- :func:`check_model`: a model's shapes, analytic Jacobians against (manifold) finite
  differences and batch selection (:mod:`quadest.conformance.models`);
- :func:`compose_config`, :func:`compose_settings`: a config as the ``quadest`` command composes
  it, for a plugin's tests (:mod:`quadest.conformance.compose`).

Each check raises ``AssertionError`` naming the first check that fails.
"""

from quadest.conformance.compose import compose_config, compose_settings
from quadest.conformance.estimators import (
    Quadratic,
    check_estimator,
    check_sigma_point_moments,
    linear_gaussian_problem,
    quadratic_moments,
)
from quadest.conformance.models import check_model
from quadest.conformance.sensors import check_sensor

__all__ = [
    "Quadratic",
    "check_estimator",
    "check_model",
    "check_sensor",
    "check_sigma_point_moments",
    "compose_config",
    "compose_settings",
    "linear_gaussian_problem",
    "quadratic_moments",
]
