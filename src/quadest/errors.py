"""Typed errors shared by the whole package."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np


class ConfigError(ValueError):
    """A configuration value is outside its allowed range.

    The message is one line that names the key, the offending value and what is allowed.
    """

    def __init__(self, key: str, value: object, allowed: str) -> None:
        self.key = key
        self.value = value
        self.allowed = allowed
        super().__init__(f"{key}={value!r} is invalid: {allowed}")

    def __reduce__(self):
        """Pickle by message and fields (a worker process sends it back to the job), whatever
        arguments a subclass's constructor takes."""
        return _restore_config_error, (type(self), str(self), self.key, self.value, self.allowed)


def _restore_config_error(cls: type, message: str, key: str, value: object, allowed: str) -> ConfigError:
    exc = cls.__new__(cls)
    ValueError.__init__(exc, message)
    exc.key, exc.value, exc.allowed = key, value, allowed
    return exc


class PluginError(ConfigError):
    """A selected plugin (an estimator, a model or a sensor) cannot be used; the message names the
    plugin and the reason, ``key`` the config key that selected it."""

    def __init__(self, name: str, message: str, key: str = "estimator") -> None:
        ValueError.__init__(self, message)
        self.key, self.value, self.allowed = key, name, message


class FilterDivergence(ArithmeticError):
    """A filter lost its numerical meaning in some Monte Carlo runs of a batch.

    ``runs`` holds the indices (within the batch) of the runs that failed, so that a batched
    filter can flag those runs and carry on with the others.
    """

    def __init__(self, message: str, runs: Sequence[int] | np.ndarray) -> None:
        self.runs = np.asarray(runs, dtype=int).ravel()
        super().__init__(f"{message} (runs {self.runs.tolist()})")
        self.reason = message


class DowndateError(FilterDivergence):
    """A Cholesky downdate would make the matrix indefinite (thesis eqs 5.19, 5.29)."""
