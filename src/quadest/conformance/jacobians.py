"""An analytic Jacobian against central differences, with a tolerance from their error bounds:
the one comparison :func:`~quadest.conformance.check_sensor` and
:func:`~quadest.conformance.check_model` make."""

from __future__ import annotations

import numpy as np

__all__ = ["assert_jacobian", "jacobian_tolerance"]


def jacobian_tolerance(
    values: np.ndarray, jacobian: np.ndarray, step: float, largest_step: float | None = None
) -> float:
    """Allowed ``|analytic − central difference|`` for differences with steps from ``step`` to
    ``largest_step`` (default ``step``): the round-off of the differenced values,
    ``10 eps·max|y|/step``, plus the truncation error of central differences, ``O(h²)`` times
    the third derivative, bounded by ``largest_step·max|J|`` for functions whose derivatives
    change on scales above the step. A wrong entry is off by a fraction of the entry, orders of
    magnitude above both."""
    eps = np.finfo(float).eps
    largest = step if largest_step is None else largest_step
    return float(10.0 * eps * np.abs(values).max(initial=1.0) / step + largest * np.abs(jacobian).max(initial=1.0))


def assert_jacobian(
    what: str,
    analytic: np.ndarray,
    differences: np.ndarray,
    values: np.ndarray,
    step: float,
    largest_step: float | None = None,
) -> None:
    """Raise ``AssertionError`` naming ``what`` when ``analytic`` and ``differences`` (central
    differences of a function with ``values``) differ by more than :func:`jacobian_tolerance`."""
    analytic, differences = np.asarray(analytic), np.asarray(differences)
    assert analytic.shape == differences.shape, (
        f"{what}: shape {analytic.shape}, expected {differences.shape} (central differences)"
    )
    err = float(np.abs(analytic - differences).max(initial=0.0))
    tol = jacobian_tolerance(values, differences, step, largest_step)
    assert err <= tol, f"{what} differs from central differences by {err:.2e} (allowed {tol:.2e})"
