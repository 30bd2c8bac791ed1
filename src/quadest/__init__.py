"""quadest: comparing nonlinear state estimators on a micro-quadrotor.

The centre is the square-root UKF of a quadrotor thesis (chapter 5, eqs 5.1–5.29), run beside
filterpy's EKF and UKF on one shared quadrotor model with a MIMU.

The Python API (``docs/python-api.md``, :mod:`quadest.app.python_api`): :func:`compose` a config,
:func:`make_data`, :func:`run_estimators`, :func:`tables`, or the whole :func:`run_job`; a bad
value is a :class:`ConfigError`. They are imported on first use, so that ``import quadest`` (which
every module of the package runs first) stays light and below the layers of ``docs/layout.md``.
"""

from __future__ import annotations

__version__ = "0.1.0"

__all__ = ["ConfigError", "ValidatedConfig", "compose", "make_data", "run_estimators", "run_job", "tables"]


def __getattr__(name: str) -> object:
    """The API's names, imported from :mod:`quadest.app.python_api` on first use (PEP 562)."""
    if name in __all__:
        from quadest.app import python_api

        return getattr(python_api, name)
    raise AttributeError(f"module 'quadest' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted([*globals(), *__all__])
