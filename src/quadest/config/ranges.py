"""Range-check primitives of the pre-run validation: each raises a one-line
:class:`~quadest.errors.ConfigError` naming the key, the value and what is allowed. An infinite or
NaN value is named as such (``inf is not a finite number``), not as out of range."""

from __future__ import annotations

import math

from quadest.errors import ConfigError


def _finite_number(key: str, value, what: str) -> None:
    """``value`` must be a finite real number (an infinite or NaN one is named as such)."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ConfigError(key, value, f"not a number; {what}")
    if not math.isfinite(value):
        raise ConfigError(key, value, f"{value} is not a finite number; {what}")


def require_positive(key: str, value, what: str = "must be > 0") -> None:
    """``value`` must be a finite number > 0."""
    _finite_number(key, value, what)
    if not value > 0:
        raise ConfigError(key, value, what)


def require_non_negative(key: str, value, what: str = "must be >= 0 (a standard deviation or error level)") -> None:
    """``value`` must be a finite number >= 0."""
    _finite_number(key, value, what)
    if not value >= 0:
        raise ConfigError(key, value, what)
