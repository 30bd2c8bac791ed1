"""A model is one registration: the pendulum of docs/models.md (``tests/plugins/pendulum_model.py``
and its YAML) registered from outside the package through the ``quadest.models`` entry points,
run end to end, its data checked against its equations, its PCRLB called a bound, its bad
settings refused; and the errors a model plugin author meets."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from omegaconf import OmegaConf

from plugin_site import PLUGINS, fake_site, fenced_blocks, quadest
from quadest.app.settings import data_settings
from quadest.evaluation.pcrlb import pcrlb_caption, pcrlb_is_bound, pcrlb_variances
from quadest.montecarlo.streams import STREAMS
from quadest.simulation import registry
from quadest.simulation.spec import ModelSpec

ENTRY_POINTS = "[quadest.models]\npendulum = pendulum_model:MODEL\n"


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    return fake_site(tmp_path_factory.mktemp("site"), ENTRY_POINTS)


@pytest.fixture
def registered(site, monkeypatch):
    """The pendulum registered in this process through its entry point, as an installed package
    registers it; the registry forgets it afterwards."""
    monkeypatch.syspath_prepend(str(site))
    monkeypatch.syspath_prepend(str(PLUGINS))
    registry.discover.cache_clear()
    yield registry.model_specs()
    registry.discover.cache_clear()


def test_the_docs_walk_through_the_tested_files():
    """docs/models.md shows the plugin's module and YAML in full, as the tests run them."""
    blocks = [b.strip() for b in fenced_blocks("models.md")]
    assert (PLUGINS / "pendulum_model.py").read_text().strip() in blocks
    assert (PLUGINS / "conf" / "model" / "pendulum.yaml").read_text().strip() in blocks


def test_the_entry_point_registers_the_model(registered):
    spec = registered["pendulum"]
    assert isinstance(spec, ModelSpec) and spec.pcrlb_is_bound
    assert pcrlb_is_bound("pendulum") and "not a bound" not in pcrlb_caption("pendulum")
    assert not pcrlb_is_bound("quadrotor") and not pcrlb_is_bound("no_such_model")


def pendulum_config(spec: ModelSpec, **model):
    node = OmegaConf.structured(spec.schema(**model))
    return OmegaConf.create({"runs": 3, "seed": 17, "duration": 2.0, "sample_period": 0.01, "model": node})


def stream(seed: int, run: int, name: str) -> np.random.Generator:
    """Run ``run``'s stream ``name``, as :mod:`quadest.montecarlo.streams` documents it."""
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(run, STREAMS.index(name))))


def test_the_data_follow_the_pendulum_equations(registered):
    """An independent recursion θ⁺ = θ + T ω + w_θ, ω⁺ = ω − T (g/l) sin θ + w_ω, z = sin θ + v,
    with the draws of each run's process and measurement streams, gives the builder's data."""
    cfg = pendulum_config(registered["pendulum"], length=0.5, rate_noise=0.02)
    data = registry.build_data(data_settings(cfg))
    T, w2, K1 = 0.01, 9.81 / 0.5, 201
    assert data.truth.shape == (3, K1, 2) and data.measurements.shape == (3, K1, 1)
    for i in range(3):
        w = stream(17, i, "process").standard_normal((K1, 2)) * [1e-4, 0.02]
        v = stream(17, i, "measurement").standard_normal((K1, 1)) * 0.05
        x = np.empty((K1, 2))
        x[0] = [0.5, 0.0]
        for k in range(1, K1):
            x[k] = [x[k - 1, 0] + T * x[k - 1, 1], x[k - 1, 1] - T * w2 * np.sin(x[k - 1, 0])] + w[k]
        np.testing.assert_allclose(data.truth[i], x, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(data.measurements[i], np.sin(x[:, :1]) + v, rtol=1e-12, atol=1e-12)


def test_the_data_key_covers_a_model_plugins_source(registered, monkeypatch):
    """quadest's code version does not cover a plugin model: the digest of its package's source is
    in the data key, and a plugin without readable source leaves the job uncached."""
    from quadest.app.settings import data_key, plugin_digests
    from quadest.cache import keys

    cfg = pendulum_config(registered["pendulum"])
    assert plugin_digests(cfg) == {"model": keys.module_digest("pendulum_model")}
    assert len(plugin_digests(cfg)["model"]) == 64
    before = data_key(cfg)
    monkeypatch.setattr(keys, "_module_source_digest", lambda top: "edited")
    assert data_key(cfg) not in (before, None)
    monkeypatch.setattr(keys, "_module_source_digest", lambda top: None)
    assert data_key(cfg) is None


@pytest.mark.slow
def test_no_filter_beats_the_pendulum_bound(registered):
    """The PCRLB is a bound here (the truth is the filter model): the EKF's and the SR-UKF's pooled
    MSE over 100 runs of 4 s is not below it beyond Monte Carlo error (``floor − t·SE``, t the
    one-sided Student quantile at 1 % over the 4 comparisons)."""
    from scipy import stats

    from quadest.estimators.registry import build_estimator
    from quadest.runner import run_estimator

    cfg = pendulum_config(registered["pendulum"])
    cfg.runs, cfg.duration = 100, 4.0
    data = registry.build_data(data_settings(cfg))
    floor = pcrlb_variances(data)[1:].mean(axis=0)
    t = stats.t.ppf(1.0 - 0.01 / 4, 99)
    for name in ("ekf", "srukf"):
        result = run_estimator(name, build_estimator(name, {"kind": name}, data.model), data, 1e6)
        per_run = result.sq_error_sum / result.steps[:, None]
        pooled, se = per_run.mean(axis=0), per_run.std(axis=0, ddof=1) / np.sqrt(per_run.shape[0])
        assert (pooled >= floor - t * se).all(), (name, (pooled - floor) / se)


@pytest.mark.slow
def test_a_comparison_runs_end_to_end(site, tmp_path):
    out = tmp_path / "run"
    args = ["model=pendulum", "estimator=[ekf,srukf]", "runs=20", "duration=4", "progress=false"]
    proc = quadest([*args, "output.figures=false", "cache.enabled=false", f"hydra.run.dir={out}"], tmp_path, site)
    assert proc.returncode == 0, proc.stderr
    assert "posterior Cramér-Rao bound (the truth follows the filter model)" in proc.stdout
    table = pd.read_csv(out / "metrics.csv")
    assert set(table["estimator"]) == {"ekf", "srukf"} and set(table["state"]) == {"theta", "omega"}
    assert not table["diverged"].any()
    summary = json.loads((out / "summary.json").read_text())
    assert summary["labels"]["model"] == "pendulum"


@pytest.mark.parametrize(
    ("override", "expected"),
    [
        ("model.lenght=2.0", "lenght"),  # not a key of the schema
        ("model.length=-1.0", "model.length=-1.0 is invalid: must be > 0"),
        ("model.initial_std=[0.2]", "model.initial_std=[0.2] is invalid: must list 2 values"),
    ],
)
@pytest.mark.slow
def test_bad_settings_are_refused_with_one_line(site, tmp_path, override, expected):
    proc = quadest(["model=pendulum", override, f"hydra.run.dir={tmp_path / 'o'}"], tmp_path, site)
    assert proc.returncode == 2
    errors = [line for line in proc.stderr.splitlines() if line.startswith("quadest: error:")]
    assert len(errors) == 1 and expected in errors[0], proc.stderr
    assert "Traceback" not in proc.stderr


@pytest.mark.slow
def test_an_unknown_model_name_lists_the_options(tmp_path, site):
    proc = quadest(["model.name=pendulm", f"hydra.run.dir={tmp_path / 'o'}"], tmp_path, site)
    assert proc.returncode == 2
    assert "model.name='pendulm' is invalid: one of [" in proc.stderr and "'pendulum'" in proc.stderr


BROKEN = (
    "[quadest.models]\nquadrotor = pendulum_model:MODEL\nbroken = no_such_module_xyz:MODEL\n"
    "notaspec = json:JSONDecoder\nmisnamed = pendulum_model:MODEL\n"
)


@pytest.fixture(scope="module")
def broken_site(tmp_path_factory):
    """The broken entry points, and a YAML for the one that fails to import (its package ships it)."""
    conf = tmp_path_factory.mktemp("conf")
    (conf / "model").mkdir()
    (conf / "model" / "broken.yaml").write_text("defaults:\n  - /schema/model/broken@_here_\n\nname: broken\n")
    return fake_site(tmp_path_factory.mktemp("broken"), BROKEN, name="fake-models", conf=conf)


def test_broken_model_plugins_are_reported_and_refused(broken_site, monkeypatch):
    monkeypatch.syspath_prepend(str(broken_site))
    monkeypatch.syspath_prepend(str(PLUGINS))
    registry.discover.cache_clear()
    try:
        found = registry.discover()
        specs, problems = found.usable, found.problems
        assert specs["quadrotor"].build.__module__ == "quadest.simulation.quadrotor_data"  # the built-in stays
        assert "collides with the built-in model 'quadrotor'" in problems["quadrotor"]
        assert "failed to import: ModuleNotFoundError" in problems["broken"]
        assert "is not a quadest.simulation.spec.ModelSpec" in problems["notaspec"]
        assert "named 'pendulum', not 'misnamed'" in problems["misnamed"]
        assert all("fake-models" in message and "\n" not in message for message in problems.values())
        assert set(specs).isdisjoint({"broken", "notaspec", "misnamed"})
    finally:
        registry.discover.cache_clear()


@pytest.mark.parametrize("selection", ["model=broken", "model.name=broken"])
@pytest.mark.slow
def test_selecting_a_broken_model_plugin_gives_one_line(broken_site, tmp_path, selection):
    """Selected by its YAML (whose schema quadest could not register) or by name."""
    proc = quadest([selection, f"hydra.run.dir={tmp_path / 'o'}"], tmp_path, broken_site)
    assert proc.returncode == 2
    errors = [line for line in proc.stderr.splitlines() if line.startswith("quadest: error:")]
    assert len(errors) == 1 and "'broken = no_such_module_xyz:MODEL' of fake-models failed to import" in errors[0]
    assert "Traceback" not in proc.stderr


@pytest.mark.slow
def test_broken_model_plugins_do_not_stop_other_runs(broken_site, tmp_path):
    args = ["model=linear", "runs=1", "duration=1", "progress=false", "output.figures=false", "cache.enabled=false"]
    proc = quadest([*args, f"hydra.run.dir={tmp_path / 'o'}"], tmp_path, broken_site)
    assert proc.returncode == 0, proc.stderr
    assert "collides with the built-in model 'quadrotor'" in proc.stderr
    assert proc.stderr.count("quadest: warning: model plugin") == 4
