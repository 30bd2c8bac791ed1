"""Cache keys: what determines a job's Monte Carlo data and one estimator's result.

A key is the SHA-256 of a canonical JSON text (sorted keys, no spaces) of everything the cached
value depends on (``docs/cache.md``):

- **data key**: the resolved job config without the keys listed in :data:`NOT_DATA_KEYS` (the
  estimators, parallelism, output settings, ...), plus :func:`code_version`. A top-level key that
  is not in that list (a new one, too) is part of the data key: an unknown key costs a cache miss,
  never a wrong hit.
- **estimator key**: the data key, the estimator's label and resolved config node, the settings
  of the runner that change its result (``divergence_bound``, the number of saved runs) and, for
  an estimator class from outside the quadest package, the digest of that class's top-level
  package or module source (:func:`plugin_digest`). A class whose source cannot be found is never
  cached.
"""

from __future__ import annotations

import hashlib
import json
import platform
import sys
from collections.abc import Iterable, Mapping
from functools import cache
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import Any

from omegaconf import OmegaConf

import quadest
from quadest.replay.data import log_path

FORMAT = 1  # bump when the layout of a cached value changes
NOT_DATA_KEYS = frozenset(
    {"estimator", "divergence_bound", "workers", "progress", "output", "objective", "sweep", "cache", "hydra"}
)
"""Top-level config keys that do not change the Monte Carlo data. ``sweep`` only holds values
that other keys interpolate; they are resolved into those keys before hashing."""
RESULT_LIBRARIES = ("numpy", "scipy", "filterpy", "pyulog", "ahrs")
"""Libraries whose version is part of the code version: the built-in filters compute with them, the
replay reads its log with pyulog and the attitude anchors are the ``ahrs`` package's filters."""


def digest_text(material: Mapping[str, Any]) -> str:
    """SHA-256 (hex) of the canonical JSON of ``material``."""
    text = json.dumps(material, sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode()).hexdigest()


def source_digest(files: Iterable[Path], root: Path) -> str:
    """SHA-256 (hex) over the paths (relative to ``root``) and contents of ``files``, in path order:
    an edit, an added, removed or renamed file changes it; timestamps and git state do not."""
    h = hashlib.sha256()
    for path in sorted(files, key=lambda p: p.relative_to(root).as_posix()):
        h.update(path.relative_to(root).as_posix().encode() + b"\0")
        h.update(hashlib.sha256(path.read_bytes()).digest())
    return h.hexdigest()


def _python_files(package_dir: Path) -> list[Path]:
    return [p for p in package_dir.rglob("*.py") if "__pycache__" not in p.parts]


@cache
def code_version() -> str:
    """Digest of the quadest package source (every ``.py`` file under the installed package, read
    once per process: the code this process runs), the Python version and the versions of
    :data:`RESULT_LIBRARIES`. Works outside git and in a dirty tree."""
    root = Path(quadest.__file__).parent
    versions = {}
    for name in RESULT_LIBRARIES:
        try:
            versions[name] = version(name)
        except PackageNotFoundError:
            versions[name] = None
    return digest_text(
        {"source": source_digest(_python_files(root), root), "python": platform.python_version(), **versions}
    )


@cache
def _module_source_digest(top_level: str) -> str | None:
    """Digest of a top-level module's source: every ``.py`` file of a package, or the file of a
    single module; ``None`` when there is no source file to read."""
    module = sys.modules.get(top_level)
    if module is None:
        return None
    paths = getattr(module, "__path__", None)
    if paths is not None:
        dirs = [Path(d) for d in paths]
        if not any(_python_files(d) for d in dirs):
            return None
        return digest_text({str(i): source_digest(_python_files(d), d) for i, d in enumerate(dirs)})
    file = getattr(module, "__file__", None)
    if file is None or not file.endswith(".py") or not Path(file).is_file():
        return None
    return source_digest([Path(file)], Path(file).parent)


def plugin_digest(cls: type) -> str | None:
    """What identifies the code of estimator class ``cls`` beyond :func:`code_version`: ``""`` for
    a class of the quadest package; for a plugin, the digest of the source of the top-level package
    (or single module) that defines it; ``None`` if that source cannot be read, and then the
    estimator is never cached. Code the plugin imports from other packages is not covered."""
    module = cls.__module__
    if module == "quadest" or module.startswith("quadest."):
        return ""
    return _module_source_digest(module.split(".")[0])


def data_material(cfg) -> dict[str, Any]:
    """The resolved config entries that determine the Monte Carlo data; for a replay
    (``source``) also the digest of the log file's bytes, so a changed log at the same path misses."""
    resolved = OmegaConf.to_container(cfg, resolve=True)
    material = {key: value for key, value in resolved.items() if key not in NOT_DATA_KEYS}
    if resolved.get("source") is not None:
        path = log_path(cfg)
        material["source_log"] = source_digest([path], path.parent)
    return material


def data_key(cfg) -> str:
    """Key of the Monte Carlo data of job config ``cfg``."""
    return digest_text({"format": FORMAT, "kind": "data", "code": code_version(), "config": data_material(cfg)})


def estimator_key(
    data: str, label: str, node: Mapping[str, Any], cls: type, divergence_bound: float, saved_runs: int
) -> str | None:
    """Key of the result of estimator ``label`` (resolved config ``node``, class ``cls``) on the
    data of key ``data``; ``None`` if it must not be cached (a plugin without readable source)."""
    plugin = plugin_digest(cls)
    if plugin is None:
        return None
    return digest_text(
        {
            "format": FORMAT,
            "kind": "estimator",
            "data": data,
            "label": label,
            "node": dict(node),
            "class": f"{cls.__module__}.{cls.__qualname__}",
            "plugin": plugin,
            "divergence_bound": float(divergence_bound),
            "saved_runs": int(saved_runs),
        }
    )
