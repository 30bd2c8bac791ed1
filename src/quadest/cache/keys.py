"""Cache keys: what determines a job's Monte Carlo data and one estimator's result.

A key is the SHA-256 of a canonical JSON text (sorted keys, no spaces) of everything the cached
value depends on (``docs/cache.md``). Every leaf of the resolved job config is in exactly one of
three places:

- :data:`RESULT_NEUTRAL`, the one declared list of settings that change no number (progress bars,
  processes, figures, the cache's own settings, ...): in no key;
- the **estimator key**: the estimator's own node (``estimator.<label>``) and the runner settings
  :data:`RUNNER_KEYS`, with the data key, the estimator's label and, for an estimator class from
  outside the quadest package, the digest of that class's top-level package or module source
  (:func:`plugin_digest`; a class whose source cannot be found is never cached);
- the **data key**: every other leaf (a new key too: an unknown key costs a cache miss, never a
  wrong hit), plus :func:`code_version`, the backend of the compiled numerics
  (``QUADEST_KERNELS``, an environment setting) and, for a model or sensor from outside the quadest
  package, the digest of its package's source (:func:`module_digest`; a plugin whose source cannot
  be found makes the job uncached).

``tests/test_cache_keys_property.py`` checks this for every leaf of every config group option.
"""

from __future__ import annotations

import copy
import hashlib
import json
import platform
import sys
from collections.abc import Iterable, Mapping
from functools import cache
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import Any

from quadest.numerics.square_root import kernel_backend
from quadest.replay.data import log_path
from quadest.simulation.recorded import recording_files

PACKAGE = Path(__file__).parent.parent
"""The folder of the quadest package this module belongs to (not ``quadest.__file__``: no layer
imports the package root, which sits above them all, docs/layout.md)."""
FORMAT = 1  # bump when the layout of a cached value changes
RESULT_NEUTRAL = (
    "progress",
    "workers",
    "output.figures",
    "output.per_estimator_figures",
    "objective",
    "metrics",
    "cache",
    "sweep",
    "hydra",
    "decision",
)
"""Config paths (a node stands for its whole subtree) that change no cached value, and so are in
no key: progress bars, worker processes, which figures are drawn, the tuning objective (computed
from ``summary.json`` after the job), the cache's own settings, Hydra's output folders and
launchers, the windows of the windowed measures (``metrics``: applied to per-step sums every result
keeps), ``sweep``, which only holds values that other keys interpolate (they are resolved into
those keys before hashing), and ``decision``, how a ``runs=auto`` job decides how many runs to
make (each of its batches is keyed by its own runs, docs/experiments.md). The one place where a
setting is declared result-neutral."""
RUNNER_KEYS = ("divergence_bound", "output.saved_runs")
"""Settings of the runner (:func:`quadest.runner.run_estimator`): every estimator's result depends
on them, the data does not. They are in the estimator key."""
ESTIMATORS = "estimator"
"""The node of the estimators: ``estimator.<label>`` is in that estimator's key only."""
NOT_DATA_KEYS = (*RESULT_NEUTRAL, *RUNNER_KEYS, ESTIMATORS)
"""Config paths left out of the data key."""
RESULT_LIBRARIES = ("numpy", "scipy", "filterpy", "pyulog", "ahrs", "numba")
"""Libraries whose version is part of the code version: the built-in filters compute with them, the
replay reads its log with pyulog, the attitude anchors are the ``ahrs`` package's filters and numba
compiles the square-root kernels and the quadrotor model's ``f``/``h``."""


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


def package_version(root: Path) -> str:
    """Digest of the package source under ``root`` (every ``.py`` file in it and in all its
    subpackages, at any depth), the Python version and the versions of :data:`RESULT_LIBRARIES`."""
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
def code_version() -> str:
    """:func:`package_version` of the installed quadest package, read once per process (the code
    this process runs). Works outside git and in a dirty tree."""
    return package_version(PACKAGE)


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


def module_digest(module: str) -> str | None:
    """What identifies the code of module ``module`` beyond :func:`code_version`: ``""`` for a
    module of the quadest package; for a plugin's module, the digest of the source of its top-level
    package (or single module); ``None`` if that source cannot be read, and then what it computes is
    never cached. Code the plugin imports from other packages is not covered."""
    if module == "quadest" or module.startswith("quadest."):
        return ""
    return _module_source_digest(module.split(".")[0])


def plugin_digest(cls: type) -> str | None:
    """:func:`module_digest` of the module that defines estimator (or sensor) class ``cls``."""
    return module_digest(cls.__module__)


def without_paths(tree: dict[str, Any], paths: Iterable[str]) -> dict[str, Any]:
    """``tree`` (nested dicts, changed in place and returned) without the dotted ``paths``."""
    for path in paths:
        *parents, last = path.split(".")
        node = tree
        for key in parents:
            node = node.get(key) if isinstance(node, dict) else None
        if isinstance(node, dict):
            node.pop(last, None)
    return tree


def data_material(resolved: dict[str, Any]) -> dict[str, Any]:
    """What determines the Monte Carlo data: the resolved config ``resolved`` (a plain dict, as
    ``OmegaConf.to_container(cfg, resolve=True)`` gives it) without :data:`NOT_DATA_KEYS`; for a
    replay (``source``) also the digest of the log file's bytes, so a changed log at the same path
    misses; for data read from a file or folder (``model.recording``) the digest of the files it is
    read from."""
    material = without_paths(copy.deepcopy(resolved), NOT_DATA_KEYS)
    if resolved.get("source") is not None:
        path = log_path(resolved["source"].get("path"))
        material["source_log"] = source_digest([path], path.parent)
    recording = (resolved.get("model") or {}).get("recording")
    if recording is not None:
        files = recording_files(recording)
        material["recording_files"] = source_digest(files, Path(files[0]).anchor)
    return material


def resolved_data_key(resolved: dict[str, Any], plugins: Mapping[str, str] | None = None) -> str:
    """Key of the Monte Carlo data of the resolved job config ``resolved`` (a plain dict).

    ``plugins`` maps each model or sensor plugin the data is made with (``"model"``,
    ``"sensor.<name>"``) to its :func:`module_digest`: an edit to a plugin's source is a miss. The
    package's own models and sensors are in :func:`code_version` and are left out of it, so a job
    without plugins keeps its key.

    It also holds the backend of the compiled numerics (``QUADEST_KERNELS``, numba or numpy:
    :func:`quadest.numerics.square_root.kernel_backend`), an environment setting read at every
    call: the square-root kernels, which every estimator's NEES and NIS go through, and the
    quadrotor model's compiled ``f``/``h`` agree with their numpy references only to round-off,
    and their step times differ. Through the data key it reaches every estimator key."""
    material = {
        "format": FORMAT,
        "kind": "data",
        "code": code_version(),
        "kernels": kernel_backend(),
        "config": data_material(resolved),
    }
    if plugins:
        material["plugins"] = dict(plugins)
    return digest_text(material)


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
