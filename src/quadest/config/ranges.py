"""Range-check primitives of the pre-run validation: each raises a one-line
:class:`~quadest.errors.ConfigError` naming the key, the value and what is allowed."""

from __future__ import annotations

import math

from quadest.errors import ConfigError


def require_positive(key: str, value, what: str = "must be > 0") -> None:
    """``value`` must be a finite number > 0."""
    if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
        raise ConfigError(key, value, what)


def require_non_negative(key: str, value, what: str = "must be >= 0 (a standard deviation or error level)") -> None:
    """``value`` must be a finite number >= 0."""
    if not (isinstance(value, int | float) and math.isfinite(value) and value >= 0):
        raise ConfigError(key, value, what)
