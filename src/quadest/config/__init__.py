"""Configuration primitives every layer may use: where the YAML tree lives
(:mod:`~quadest.config.paths`), the range-check primitives (:mod:`~quadest.config.ranges`) and the
closed loop's settings (:mod:`~quadest.config.closed_loop`).

The schemas of the whole tree and the checks across features are in the application layer
(:mod:`quadest.app.schema`, :mod:`quadest.app.validate`).
"""

from quadest.config.paths import config_dir

__all__ = ["config_dir"]
