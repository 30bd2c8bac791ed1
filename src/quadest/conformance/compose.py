"""A config as the ``quadest`` command composes it, for a plugin's tests: the settings a model
builder, a sensor or an estimator is handed in a job, from the same YAML tree and overrides.

Both are thin uses of :func:`quadest.compose` (``docs/python-api.md``), which a plugin's own
config group joins like a built-in one (``docs/plugins.md``).
"""

from __future__ import annotations

from collections.abc import Sequence

from omegaconf import DictConfig

from quadest.app.python_api import compose, compose_unchecked
from quadest.app.settings import data_settings
from quadest.config.settings import DataSettings

__all__ = ["compose_config", "compose_settings"]


def compose_config(overrides: Sequence[str] | None = None, checked: bool = True) -> DictConfig:
    """The composed root config of ``quadest <overrides>``, e.g.
    ``compose_config(["model=my_model", "runs=2"])``.

    Args:
        overrides: Hydra overrides, as on the command line.
        checked: run the command's checks (:func:`quadest.compose`: ranges, unknown keys, the
            model's and each sensor's ``validate``) and raise their ``ConfigError``; ``False``
            composes only, to hand a refused value to the check under test.
    """
    overrides = list(overrides or ())
    return compose(overrides).composed if checked else compose_unchecked(overrides)


def compose_settings(overrides: Sequence[str] | None = None, checked: bool = True) -> DataSettings:
    """The typed data settings of ``quadest <overrides>``: what a model's ``build`` and
    ``validate`` and a sensor take (``settings.model``, ``settings.model.aiding``); ``checked``
    as in :func:`compose_config`."""
    overrides = list(overrides or ())
    return compose(overrides).settings.data if checked else data_settings(compose_unchecked(overrides))
