"""Cache-key completeness, as properties over the whole config family (docs/cache.md, "Keys").

A cached value may only be served for a config that would compute the same value. So for every
leaf of every composed config (each option of each config group, the experiments included, and
the job keys), changing that leaf alone must change the key of everything it can affect:

- a leaf under :data:`quadest.cache.keys.RESULT_NEUTRAL` (the one declared list) changes no key;
- a leaf of ``estimator.<label>`` changes that estimator's key and no other key;
- a runner setting (:data:`~quadest.cache.keys.RUNNER_KEYS`) changes every estimator key, not the
  data key;
- every other leaf, whatever it is called and whenever it was added, changes the data key and with
  it every estimator key.

The leaves are read from the composed configs, which hold every field of their dataclass schemas
(``quadest.app.schema``) with its default, so a field added to a schema, or a new option in
``conf/``, is covered without touching this file. Only keys are computed here; nothing is run.
And the code version follows every source file of the package, in every subpackage.
"""

from __future__ import annotations

import copy
import math
import shutil
from collections.abc import Iterator
from pathlib import Path

import pytest
from omegaconf import DictConfig, OmegaConf

import quadest
import quadest.app.estimator_runs as estimator_runs
import quadest.app.job as job
from helpers import compose_config
from quadest.app.estimator_runs import RunSettings
from quadest.app.settings import data_key
from quadest.cache import keys
from quadest.cache.lookup import JobCache
from quadest.cache.store import CacheStore
from quadest.config.paths import config_dir
from quadest.estimators.registry import builtin_estimators
from quadest.quadrotor.scenario_registry import builtin_scenario_classes
from quadest.replay.data import log_path
from quadest.simulation.recorded import resolve_recording
from quadest.simulation.registry import builtin_model_specs

LeafPath = tuple[str | int, ...]


def group_options() -> list[list[str]]:
    """One override list per option of every config group under ``conf/`` (Hydra's own launcher
    configs aside), plus the default config: ``model=ins``, ``sensor/gps=rtk``, ``experiment=...``,
    and every estimator at once."""
    root = Path(config_dir())
    options: list[list[str]] = [[]]
    estimators = []
    for file in sorted(root.rglob("*.yaml")):
        group = file.parent.relative_to(root).as_posix()
        if group == "." or group.startswith("hydra"):
            continue
        if group == "estimator":
            estimators.append(file.stem)
        else:
            options.append([f"{group}={file.stem}"])
    options.append([f"estimator=[{','.join(estimators)}]"])
    return options


OPTIONS = group_options()


def leaves(node, path: LeafPath = ()) -> Iterator[tuple[LeafPath, object]]:
    """Every leaf of a resolved config: scalars, list items, and empty dicts or lists (which a
    change can fill)."""
    if isinstance(node, dict) and node:
        for key, child in node.items():
            yield from leaves(child, (*path, key))
    elif isinstance(node, list) and node:
        for i, child in enumerate(node):
            yield from leaves(child, (*path, i))
    else:
        yield path, node


def unset_node(cfg, path: LeafPath) -> bool:
    """Whether ``path`` is an optional config node left null (``source: null``): its fields are
    leaves of the options that set it (``experiment=px4_replay``), not values to change here."""
    node = cfg
    for key in path:
        node = node._get_node(key)
    return isinstance(node, DictConfig) and node._is_none()


def dotted(path: LeafPath) -> str:
    return ".".join(map(str, path))


def under(path: LeafPath, prefixes: tuple[str, ...]) -> bool:
    text = dotted(path)
    return any(text == p or text.startswith(p + ".") for p in prefixes)


def changed(path: LeafPath, value, cfg, tmp_path: Path):
    """Another value of the same kind. A log path is changed to a copy of the log under another
    name (a path must name a readable log; the name is in the replay's labels), a recording to a
    copy of the shipped one."""
    if path[-1] == "path" and path[0] == "source":
        copied = tmp_path / "copied.ulg"
        if not copied.exists():
            shutil.copyfile(log_path(cfg.source.path), copied)
        return str(copied)
    if path == ("model", "recording"):  # a path must name a readable recording (its bytes are in the key)
        copied = tmp_path / "copied_recording.json"
        if not copied.exists():
            shutil.copyfile(resolve_recording("sarkka-svensson-2023/pendulum.json"), copied)
        return str(copied)
    if isinstance(value, bool):
        return not value
    if isinstance(value, int):  # down: a count above another (saved runs above runs) may be clipped
        return value - 1 if value > 0 else 1
    if isinstance(value, float):
        return value + 0.5 * (abs(value) or 1.0) if math.isfinite(value) else 1.0
    if isinstance(value, str):
        return value + "_changed"
    if isinstance(value, dict):
        return {"added": 1}
    if isinstance(value, list):
        return ["added"]
    assert value is None, f"{dotted(path)}: a leaf of type {type(value).__name__} the test cannot change"
    return "changed"


def with_value(resolved: dict, path: LeafPath, value) -> dict:
    tree = copy.deepcopy(resolved)
    node = tree
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value
    return tree


def all_keys(resolved: dict, tmp_path: Path) -> tuple[str, dict[str, str | None]]:
    """The data key and every estimator's result key of the resolved config ``resolved``, computed
    as every job computes them (:func:`quadest.app.estimator_runs.run_estimators`)."""
    cache = JobCache(CacheStore(tmp_path / "never-written"), keys.resolved_data_key(resolved))
    bound = float(resolved["divergence_bound"])
    saved_runs = min(int(resolved["output"]["saved_runs"]), int(resolved["runs"]))
    return cache.data_key, {
        label: estimator_runs._result_key(cache, label, node, RunSettings(bound, saved_runs))
        for label, node in resolved["estimator"].items()
    }


@pytest.mark.parametrize("overrides", OPTIONS, ids=lambda o: " ".join(o) or "defaults")
@pytest.mark.slow
def test_every_leaf_of_the_config_changes_the_keys_of_what_it_affects(overrides, tmp_path):
    """Each leaf changed alone, with the expectations of the module docstring."""
    cfg = compose_config(overrides)
    resolved = OmegaConf.to_container(cfg, resolve=True)
    data0, est0 = all_keys(resolved, tmp_path)
    assert data0 == data_key(cfg)
    assert all(key is not None for key in est0.values()), "every built-in estimator is cached"
    problems = []
    for path, value in leaves(resolved):
        if unset_node(cfg, path):
            continue
        data1, est1 = all_keys(with_value(resolved, path, changed(path, value, cfg, tmp_path)), tmp_path)
        kept = {label for label in est0 if est1[label] == est0[label]}
        if under(path, keys.RESULT_NEUTRAL):
            expected_data, expected_same = False, set(est0)
        elif path[0] == keys.ESTIMATORS:
            expected_data, expected_same = False, set(est0) - {path[1]}
        elif under(path, keys.RUNNER_KEYS):
            expected_data, expected_same = False, set()
        else:
            expected_data, expected_same = True, set()
        if (data1 != data0) != expected_data or kept != expected_same:
            problems.append(
                f"{dotted(path)}: data key {'changed' if data1 != data0 else 'kept'} (expected "
                f"{'changed' if expected_data else 'kept'}), estimator keys kept for {sorted(kept)} "
                f"(expected {sorted(expected_same)})"
            )
    assert not problems, "\n".join(problems)


@pytest.mark.slow
def test_the_family_covers_every_group_and_the_job_keys():
    """The property is only as wide as the configs it walks: every group option is composed, and
    together they hold the job keys, every model, sensor, scenario and estimator node."""
    groups = {o[0].split("=")[0] for o in OPTIONS if o}
    assert {"model", "sensor", "scenario", "estimator", "experiment"} <= groups
    options = {o[0] for o in OPTIONS if o}
    assert {f"model={name}" for name in builtin_model_specs()} <= options, "a registered model without a config option"
    flown = {OmegaConf.get_type(compose_config([o]).scenario) for o in options if o.startswith("scenario=")}
    assert set(builtin_scenario_classes().values()) <= flown, "a scenario schema no config option uses"
    walked = set(compose_config(OPTIONS[-1]).estimator)
    assert set(builtin_estimators()) <= walked, "a registered estimator the walk does not reach"
    top = set(OmegaConf.to_container(compose_config(), resolve=True))
    assert {"runs", "seed", "duration", "sample_period", "divergence_bound", "model", "sensor", "scenario"} <= top
    default = compose_config()
    unset = [path for path, _ in leaves(OmegaConf.to_container(default)) if unset_node(default, path)]
    for path in unset:  # an optional node left null by default is walked where an option sets it
        assert any(OmegaConf.select(compose_config(o), dotted(path)) is not None for o in OPTIONS), dotted(path)
    declared = [*keys.RESULT_NEUTRAL, *keys.RUNNER_KEYS]
    assert len(set(declared)) == len(declared), "a path is declared twice"


@pytest.mark.slow
def test_editing_any_source_file_changes_the_code_version(tmp_path, monkeypatch):
    """A copy of the installed package: appending a line to any one ``.py`` file, at any depth,
    changes :func:`~quadest.cache.keys.package_version`, and so does adding a module to a
    subpackage; the installed package's code version is that same function of its folder."""
    installed = Path(quadest.__file__).parent
    seen: list[Path] = []
    monkeypatch.setattr(keys, "package_version", lambda root: seen.append(root) or "digest of root")
    keys.code_version.cache_clear()  # read again below, and again by the next test that needs it
    try:
        assert keys.code_version() == "digest of root" and seen == [installed]
    finally:
        keys.code_version.cache_clear()
        monkeypatch.undo()
    copy_root = tmp_path / "quadest"
    shutil.copytree(installed, copy_root, ignore=shutil.ignore_patterns("__pycache__"))
    base = keys.package_version(copy_root)
    files = sorted(copy_root.rglob("*.py"))
    assert any(len(f.relative_to(copy_root).parts) > 1 for f in files), "the package has nested subpackages"
    unchanged = []
    for file in files:
        text = file.read_bytes()
        file.write_bytes(text + b"\n# edited\n")
        if keys.package_version(copy_root) == base:
            unchanged.append(file.relative_to(copy_root).as_posix())
        file.write_bytes(text)
    assert not unchanged, f"edits that keep the code version: {unchanged}"
    assert keys.package_version(copy_root) == base
    deepest = max((f.parent for f in files), key=lambda d: len(d.parts))
    (deepest / "added_module.py").write_text("")
    assert keys.package_version(copy_root) != base


def test_the_kernels_backend_is_in_every_key(monkeypatch, tmp_path):
    """``QUADEST_KERNELS`` (numba or numpy) is not a config leaf but changes numbers at round-off
    (the square-root kernels every estimator's NEES and NIS whiten through, the quadrotor model's
    compiled ``f``/``h``) and the step times: a value computed on one backend is not served on the
    other."""
    pytest.importorskip("numba")
    resolved = OmegaConf.to_container(compose_config(), resolve=True)
    monkeypatch.setenv("QUADEST_KERNELS", "numba")
    data_numba, numba = all_keys(resolved, tmp_path)
    monkeypatch.setenv("QUADEST_KERNELS", "numpy")
    data_numpy, numpy = all_keys(resolved, tmp_path)
    assert data_numba != data_numpy
    assert all(numba[label] != numpy[label] for label in numba)


SMALL = ["runs=5", "duration=0.2", "progress=false", "output.figures=false", "workers=1", "estimator=[ekf]"]


@pytest.mark.parametrize("setting", keys.RUNNER_KEYS)
def test_a_job_recomputes_its_estimators_when_a_runner_setting_changes(setting, tmp_path, monkeypatch):
    """End to end through :func:`quadest.app.job.run_job`: the job passes each runner setting into the
    estimator keys (a changed one recomputes the estimator from the cached data)."""
    runs: list[str] = []
    run = estimator_runs.run_estimator

    def counting(name, *args, **kwargs):
        runs.append(name)
        return run(name, *args, **kwargs)

    monkeypatch.setattr(estimator_runs, "run_estimator", counting)
    cfg = compose_config([*SMALL, f"cache.dir={tmp_path / 'cache'}"])
    job.run_job(cfg, tmp_path / "a")
    value = OmegaConf.select(cfg, setting)
    OmegaConf.update(cfg, setting, changed((setting,), value, cfg, tmp_path))
    summary = job.run_job(cfg, tmp_path / "b")
    assert summary["cache"]["data_from_cache"] and runs == ["ekf", "ekf"]
