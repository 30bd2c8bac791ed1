"""Configuration: where the YAML tree lives, its schemas, and the range checks."""

from quadest.config.paths import config_dir

__all__ = ["config_dir"]
