"""The config is parsed once, at the top (docs/layout.md): the application layer converts the
composed ``DictConfig`` into typed settings (:mod:`quadest.app.settings`) and hands each layer
below only those. Every job kind, with every model option, is run with spies at the points where
settings cross into the lower layers: each model option's ``ModelSpec`` (``validate``,
``state_dimension``, ``build``), the closed loop, the replay, the cache, the objective and each
estimator's node. What crosses must be typed: a dataclass instance (or a plain dict for an
estimator's node), with no ``DictConfig`` or ``ListConfig`` anywhere inside.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import pytest
from omegaconf import DictConfig, ListConfig, OmegaConf

import quadest.app.closed_loop_job as closed_loop_job
import quadest.app.estimator_runs as estimator_runs
import quadest.app.validate as app_validate
import quadest.cache.lookup as lookup
import quadest.replay.data as replay_data
import quadest.simulation.registry as registry
from helpers import compose_config
from quadest.app.job import run_job
from quadest.app.settings import data_settings, job_settings
from quadest.config.settings import DataSettings

CLOSED = ["scenario=attitude_steps", "scenario.steps=[[0.1,0.0,4.0]]", "duration=0.3"]
JOBS = {
    "quadrotor": ["duration=0.2"],
    "quadrotor_smoother": ["duration=0.2", "estimator=[srukf]", "estimator.srukf.smoother=fixed_interval"],
    "ins": ["model=ins", "duration=1.0", "estimator=[mekf]"],
    "attitude": ["model=attitude", "duration=0.5", "estimator=[mekf]"],
    "linear": ["model=linear", "duration=3", "sample_period=1"],
    "ungm": ["model=ungm", "duration=3", "sample_period=1"],
    "upf_benchmark": ["model=upf_benchmark", "duration=3", "sample_period=1"],
    "seed001_rates": ["model=seed001_rates", "duration=0.2"],
    "seed003_attitude": ["model=seed003_attitude", "duration=0.2"],
    "closed_truth": ["loop=truth", *CLOSED],
    "closed_measured": ["loop=measured", *CLOSED],
    "closed_estimate": ["loop=estimate", *CLOSED],
    "seed003_closed_estimate": ["model=seed003_attitude", "loop=estimate", *CLOSED],
    "seed003_closed_measured": ["model=seed003_attitude", "loop=measured", *CLOSED],
    "replay": ["experiment=px4_replay", "duration=6.0", "estimator=[mekf]"],
}
COMMON = ["runs=1", "workers=1", "progress=false", "output.figures=false", "estimator=[ekf]"]


def raw_nodes(value: Any, path: str) -> list[str]:
    """The paths inside ``value`` (dataclass fields, dict values, list items) that hold a raw
    ``DictConfig``/``ListConfig``."""
    if isinstance(value, DictConfig | ListConfig):
        return [f"{path} ({type(value).__name__})"]
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return [p for f in dataclasses.fields(value) for p in raw_nodes(getattr(value, f.name), f"{path}.{f.name}")]
    if isinstance(value, dict):
        return [p for k, v in value.items() for p in raw_nodes(v, f"{path}[{k!r}]")]
    if isinstance(value, list | tuple):
        return [p for i, v in enumerate(value) for p in raw_nodes(v, f"{path}[{i}]")]
    return []


@pytest.fixture
def handed(monkeypatch) -> list[tuple[str, Any]]:
    """Spies at every crossing into the layers below the application layer; the list of
    ``(where, what was handed)``."""
    calls: list[tuple[str, Any]] = []

    def spy(where: str, function):
        def wrapper(*args, **kwargs):
            calls.append((where, args[0] if args else next(iter(kwargs.values()))))
            return function(*args, **kwargs)

        return wrapper

    def spec_spy(model_spec):
        def wrapper(name):
            assert isinstance(name, str), f"model_spec handed {type(name).__name__}"
            spec = model_spec(name)
            return dataclasses.replace(
                spec,
                build=spy(f"{name}.build", spec.build),
                validate=spy(f"{name}.validate", spec.validate),
                state_dimension=spy(f"{name}.state_dimension", spec.state_dimension),
            )

        return wrapper

    monkeypatch.setattr(app_validate, "model_spec", spec_spy(app_validate.model_spec))
    monkeypatch.setattr(registry, "model_spec", spec_spy(registry.model_spec))
    monkeypatch.setattr(replay_data, "build_replay_data", spy("build_replay_data", replay_data.build_replay_data))
    for name in ("validate_replay", "validate_cache", "validate_objective"):
        monkeypatch.setattr(app_validate, name, spy(name, getattr(app_validate, name)))
    monkeypatch.setattr(closed_loop_job, "closed_loop_for", spy("closed_loop_for", closed_loop_job.closed_loop_for))
    monkeypatch.setattr(closed_loop_job, "validate_loop", spy("validate_loop", closed_loop_job.validate_loop))
    monkeypatch.setattr(lookup, "cache_dir", spy("cache_dir", lookup.cache_dir))

    def node_spy(where: str, function):
        def wrapper(label, node, *args, **kwargs):
            calls.append((where, node))
            return function(label, node, *args, **kwargs)

        return wrapper

    monkeypatch.setattr(estimator_runs, "build_estimator", node_spy("build_estimator", estimator_runs.build_estimator))
    monkeypatch.setattr(
        closed_loop_job, "build_estimator", node_spy("build_estimator", closed_loop_job.build_estimator)
    )
    return calls


@pytest.mark.parametrize("job", JOBS)
@pytest.mark.slow
def test_every_job_hands_the_layers_below_typed_settings_only(job, handed, tmp_path):
    cfg = compose_config([*COMMON, *JOBS[job], f"cache.dir={tmp_path / 'cache'}"])
    summary = run_job(cfg, tmp_path / "out")
    assert summary["status"] == "ok"
    where = {w for w, _ in handed}
    name = cfg.model.name
    assert {f"{name}.validate", f"{name}.state_dimension", "validate_cache", "validate_objective", "cache_dir"} <= where
    made = {"replay": "build_replay_data"}.get(job, "closed_loop_for" if cfg.loop != "open" else f"{name}.build")
    assert made in where and "build_estimator" in where
    for w, value in handed:
        if w == "validate_loop":
            assert isinstance(value, str)  # loop, model name, closed_loop: checked below
            continue
        assert (w == "build_estimator" and type(value) is dict) or dataclasses.is_dataclass(value), (w, type(value))
        assert not raw_nodes(value, w), raw_nodes(value, w)
    assert all(isinstance(v, DataSettings) for w, v in handed if w.endswith((".build", ".validate", "closed_loop_for")))


def test_the_typed_settings_hold_the_composed_values():
    """The conversion keeps every value: each typed node equals the composed node, resolved."""
    cfg = compose_config(["model=ins", "sensor.gyro.white_noise=0.002", "scenario=seed004_approach"])
    experiment = job_settings(cfg).experiment
    for key in ("model", "sensor", "scenario", "closed_loop", "output", "cache", "objective"):
        assert dataclasses.asdict(getattr(experiment, key)) == OmegaConf.to_container(cfg[key], resolve=True), key
    assert experiment.estimator == OmegaConf.to_container(cfg.estimator, resolve=True)
    settings = data_settings(cfg)
    assert list(settings.aiding) == list(cfg.model.aiding)
    assert (
        settings.aiding["gps"] == settings.sensor.gps and settings.aiding["magnetometer"] == settings.model.magnetometer
    )
