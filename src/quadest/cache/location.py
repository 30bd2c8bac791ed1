"""Where the cache lives and whether it is used: the ``cache`` config node (``docs/cache.md``).

``cache.dir`` if set, else ``$QUADEST_CACHE_DIR`` if set and not empty, else
``$XDG_CACHE_HOME/quadest``, else ``~/.cache/quadest``. ``cache.enabled: false`` turns the cache
off: the job then neither reads nor creates anything there.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from quadest.errors import ConfigError

ENV_VAR = "QUADEST_CACHE_DIR"


@dataclass
class CacheConf:
    """The ``cache`` node (docs/cache.md): ``dir`` null means ``$QUADEST_CACHE_DIR``, else
    ``~/.cache/quadest``. The cache is handed this node only (:mod:`quadest.app.settings`)."""

    enabled: bool = True
    dir: str | None = None


def default_cache_dir() -> Path:
    """The cache folder when ``cache.dir`` is null."""
    if os.environ.get(ENV_VAR):
        return Path(os.environ[ENV_VAR]).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base).expanduser() / "quadest"


def _setting(cache: CacheConf) -> tuple[str, str | Path]:
    """The key that sets the folder and its value."""
    if cache.dir is not None:
        return "cache.dir", cache.dir
    return (ENV_VAR, os.environ[ENV_VAR]) if os.environ.get(ENV_VAR) else ("cache.dir", default_cache_dir())


def cache_dir(cache: CacheConf) -> Path:
    """The absolute cache folder of the ``cache`` settings."""
    return Path(_setting(cache)[1]).expanduser().absolute()


def validate_cache(cache: CacheConf) -> None:
    """With the cache enabled, its folder must be a non-empty path that is not an existing file;
    raise a one-line :class:`ConfigError` naming ``cache.dir`` (or the environment variable)."""
    if not cache.enabled:
        return
    key, value = _setting(cache)
    allowed = f"a directory path (null: ${ENV_VAR}, else ~/.cache/quadest), or cache.enabled=false"
    if not str(value).strip():
        raise ConfigError(key, value, allowed)
    path = Path(value).expanduser()
    if path.exists() and not path.is_dir():
        raise ConfigError(key, str(value), f"{allowed}; it names an existing file")
