"""A sensor is one object: the built-in INS sensors through the registry, and the rangefinder of
docs/sensors.md (``tests/plugins/rangefinder_sensor.py`` and its YAML) added from outside the
package through the ``quadest.sensors`` entry points, on ``model=ins``; a velocity sensor on
``model=quadrotor``; their draws from streams of their own; and the errors a sensor plugin author
meets."""

from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest

from helpers import compose_config, compose_settings
from plugin_site import PLUGINS, fake_site, fenced_blocks, quadest
from quadest.app.schema import register_schemas
from quadest.app.validate import validate
from quadest.errors import ConfigError
from quadest.sensors import registry
from quadest.sensors.base import Sensor
from quadest.simulation.registry import build_data

ENTRY_POINTS = (
    "[quadest.sensors]\nrangefinder = rangefinder_sensor:Rangefinder\nvelocimeter = velocimeter_sensor:Velocimeter\n"
)
SHORT = ["runs=3", "duration=3", "progress=false", "output.figures=false", "cache.enabled=false"]


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    return fake_site(tmp_path_factory.mktemp("site"), ENTRY_POINTS)


@pytest.fixture
def registered(site, monkeypatch):
    """The plugin sensors registered in this process through their entry points, and the schemas
    stored again with their settings nodes; the registry forgets them afterwards."""
    monkeypatch.syspath_prepend(str(site))
    monkeypatch.syspath_prepend(str(PLUGINS))
    registry.discover.cache_clear()
    register_schemas()
    yield registry.sensor_classes()
    registry.discover.cache_clear()
    register_schemas()


def test_the_builtin_sensors_are_registered_sensors():
    sensors = registry.builtin_sensor_classes()
    assert set(sensors) == {"gps", "barometer", "vision", "magnetometer"}
    assert all(issubclass(cls, Sensor) and registry.is_builtin(cls) for cls in sensors.values())
    assert sensors["magnetometer"].key() == "model.magnetometer" and sensors["gps"].key() == "sensor.gps"


def test_the_ins_data_builder_names_no_sensor():
    """No per-sensor branch is left in the INS data builder: every sensor goes through the registry."""
    from quadest.simulation import ins_data

    source = open(ins_data.__file__).read()
    assert not any(f'"{name}"' in source for name in ("gps", "barometer", "vision", "magnetometer"))


def test_the_docs_walk_through_the_tested_files():
    blocks = [b.strip() for b in fenced_blocks("sensors.md")]
    assert (PLUGINS / "rangefinder_sensor.py").read_text().strip() in blocks
    assert (PLUGINS / "conf" / "sensor" / "rangefinder" / "lidar_lite.yaml").read_text().strip() in blocks


def _ins(aiding: str, *extra: str):
    return build_data(
        compose_settings(["model=ins", f"model.aiding={aiding}", "runs=3", "duration=3", "seed=9", *extra])
    )


def named_generator(seed: int, run: int, name: str) -> np.random.Generator:
    """The plugin stream ``name`` of run ``run`` as docs/sensors.md defines it: spawn key
    ``(run, 2³² − 1, four little-endian words of SHA-256(name))``."""
    words = np.frombuffer(hashlib.sha256(name.encode()).digest()[:16], dtype="<u4").tolist()
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(run, 2**32 - 1, *words)))


@pytest.mark.slow
def test_the_rangefinder_measures_the_height_from_its_own_stream(registered):
    """Each sample is the true height plus ``noise`` times the draws of the run's stream
    ``sensor:rangefinder:rangefinder``, at 20 Hz; adding it changes no other draw of the data."""
    with_it = _ins("[gps,rangefinder]")
    without = _ins("[gps]")
    record = with_it.sensors["rangefinder"]
    K1 = with_it.time.size
    assert record.available.sum() == len(range(0, K1, 5)) and record.available[::5].all()
    for i in range(3):
        noise = named_generator(9, i, "sensor:rangefinder:rangefinder").standard_normal(K1) * 0.02
        expected = (with_it.truth[i, :, 6] + noise)[record.available]
        np.testing.assert_allclose(record.values[i, record.available, 0], expected, rtol=0, atol=1e-15)
    for name in ("truth", "inputs", "x0"):
        np.testing.assert_array_equal(getattr(with_it, name), getattr(without, name))
    np.testing.assert_array_equal(with_it.sensors["gps"].values, without.sensors["gps"].values)
    assert with_it.labels["aiding"] == "gps+rangefinder"


@pytest.mark.slow
def test_a_sensor_draws_the_same_numbers_from_a_plugin_or_from_the_repository(registered, monkeypatch):
    """A plugin's streams are named after the sensor, not after where it is installed."""
    from quadest.simulation import aiding

    plugin = _ins("[rangefinder]").sensors["rangefinder"].values
    monkeypatch.setattr(aiding, "is_builtin", lambda cls: True)
    np.testing.assert_array_equal(_ins("[rangefinder]").sensors["rangefinder"].values, plugin)


def test_the_data_key_covers_a_sensor_plugins_source(registered, monkeypatch):
    """quadest's code version does not cover a plugin sensor: the digest of its package's source
    is in the data key (an edit is a miss, :func:`quadest.cache.keys.module_digest` reads the files),
    the built-in sensors add nothing, and a plugin without readable source leaves the job uncached."""
    from omegaconf import OmegaConf

    from quadest.app.settings import data_key, plugin_digests
    from quadest.cache import keys

    cfg = compose_config(["model=ins", "model.aiding=[gps,rangefinder]", "estimator=[mekf]"])
    digests = plugin_digests(cfg)
    assert digests == {"model": "", "sensor.gps": "", "sensor.rangefinder": keys.module_digest("rangefinder_sensor")}
    assert len(digests["sensor.rangefinder"]) == 64
    without = compose_config(["model=ins", "model.aiding=[gps]", "estimator=[mekf]"])
    assert data_key(without) == keys.resolved_data_key(OmegaConf.to_container(without, resolve=True))
    before = data_key(cfg)
    monkeypatch.setattr(keys, "_module_source_digest", lambda top: "edited" if top == "rangefinder_sensor" else None)
    assert data_key(cfg) not in (before, None)
    monkeypatch.setattr(keys, "_module_source_digest", lambda top: None)
    assert data_key(cfg) is None


def test_the_ins_places_the_rangefinder_jacobian_on_the_height(registered):
    """Through the INS's ``H_err``, ``∂h/∂δx`` is 1 at the height's error column and 0 elsewhere
    (its agreement with finite differences: ``check_sensor``, tests/test_conformance_sensors.py)."""
    data = _ins("[rangefinder]")
    H = data.model.H_err(data.truth[:, 50], data.inputs[:, 50], "rangefinder")
    assert H[:, 0, 5].tolist() == [1.0] * 3 and np.count_nonzero(H) == 3


@pytest.mark.parametrize(
    ("overrides", "key", "expected"),
    [
        (["model.aiding=[gps,lidar]"], "model.aiding", "distinct names from ['barometer', 'gps'"),
        (["model.aiding=[rangefinder]", "sensor.rangefinder.noise=0"], "sensor.rangefinder.noise", "must be > 0"),
        (["model.aiding=[rangefinder]", "sensor.rangefinder.rate=30"], "sensor.rangefinder.rate", "must divide"),
        (["model=quadrotor", "model.aiding=[rangefinder]"], "model.aiding", "measures position, which model=quadrotor"),
        (["model=quadrotor", "model.aiding=[velocimeter]", "loop=truth"], "model.aiding", "need loop=open"),
    ],
)
def test_bad_sensor_settings_fail_before_any_work(registered, overrides, key, expected):
    with pytest.raises(ConfigError) as info:
        validate(compose_config(["model=ins", "estimator=[mekf]", *overrides]))
    assert info.value.key == key and expected in str(info.value) and "\n" not in str(info.value)


@pytest.mark.slow
def test_the_rangefinder_runs_on_the_ins_from_the_command_line(site, tmp_path):
    out = tmp_path / "run"
    args = ["model=ins", "model.aiding=[gps,rangefinder]", "+sensor/rangefinder=lidar_lite", "estimator=[mekf]"]
    proc = quadest([*args, *SHORT, f"hydra.run.dir={out}"], tmp_path, site)
    assert proc.returncode == 0, proc.stderr
    assert "rangefinder" in proc.stdout  # NIS per sensor
    table = pd.read_csv(out / "metrics.csv")
    assert set(table["aiding"]) == {"gps+rangefinder"} and not table["diverged"].any()
    config = (out / "config.yaml").read_text()
    assert "rangefinder:\n    rate: 50.0\n    noise: 0.025\n    max_range: 40.0" in config  # the YAML's values


def _velocity_rmse(data, name: str = "ekf") -> np.ndarray:
    from quadest.estimators.registry import build_estimator
    from quadest.runner import run_estimator

    result = run_estimator(name, build_estimator(name, {"kind": name}, data.model), data, 1e6)
    return np.sqrt(np.nanmean(result.rmse[:, :3] ** 2, axis=0))


@pytest.mark.slow
def test_a_velocity_sensor_on_the_quadrotor_informs_the_filter(registered):
    """``model=quadrotor`` takes further sensors too: a 20 Hz velocity sensor with 1 cm/s noise
    brings the EKF's velocity RMSE well below what the MIMU alone gives (under 0.7 of it), on the same MIMU
    draws; its Jacobian is the analytic one."""
    base = ["model=quadrotor", "runs=4", "duration=4", "seed=3"]
    alone = build_data(compose_settings(base))
    sensor = ["model.aiding=[velocimeter]", "sensor.velocimeter.rate=20", "sensor.velocimeter.noise=0.01"]
    aided = build_data(compose_settings([*base, *sensor]))
    np.testing.assert_array_equal(alone.measurements, aided.measurements)
    np.testing.assert_array_equal(alone.truth, aided.truth)
    x, u = aided.truth[:, 10], aided.model.filter_input(aided.inputs[:, 10], aided.companion_truth[:, 10])
    H = aided.model.H_err(x, u, "velocimeter")
    np.testing.assert_array_equal(H, np.broadcast_to(np.eye(3, aided.model.n), H.shape))
    assert (_velocity_rmse(aided) < 0.7 * _velocity_rmse(alone)).all()  # about 0.3 to 0.55 of it


@pytest.mark.slow
def test_a_velocity_sensor_runs_on_the_quadrotor_from_the_command_line(site, tmp_path):
    out = tmp_path / "run"
    args = ["model.aiding=[velocimeter]", "+sensor/velocimeter=px4flow", "estimator=[ekf,srukf]"]
    proc = quadest([*args, *SHORT, f"hydra.run.dir={out}"], tmp_path, site)
    assert proc.returncode == 0, proc.stderr
    table = pd.read_csv(out / "metrics.csv")
    assert set(table["aiding"]) == {"velocimeter"} and not table["diverged"].any()


BROKEN = (
    "[quadest.sensors]\ngps = rangefinder_sensor:Rangefinder\nbroken = no_such_module_xyz:Sensor\n"
    "notasensor = json:JSONDecoder\nmisnamed = rangefinder_sensor:Rangefinder\n"
)


@pytest.fixture(scope="module")
def broken_site(tmp_path_factory):
    return fake_site(tmp_path_factory.mktemp("broken"), BROKEN, name="fake-sensors", conf=None)


def test_broken_sensor_plugins_are_reported(broken_site, monkeypatch):
    monkeypatch.syspath_prepend(str(broken_site))
    monkeypatch.syspath_prepend(str(PLUGINS))
    registry.discover.cache_clear()
    try:
        found = registry.discover()
        sensors, problems = found.usable, found.problems
        assert sensors["gps"].__module__ == "quadest.sensors.gps"  # the built-in stays
        assert "collides with the built-in sensor 'gps'" in problems["gps"]
        assert "failed to import: ModuleNotFoundError" in problems["broken"]
        assert "must subclass quadest.sensors.base.Sensor" in problems["notasensor"]
        assert "named 'rangefinder', not 'misnamed'" in problems["misnamed"]
        assert all("fake-sensors" in message and "\n" not in message for message in problems.values())
    finally:
        registry.discover.cache_clear()


def test_selecting_a_broken_sensor_plugin_gives_one_line(broken_site, tmp_path):
    proc = quadest(["model=ins", "model.aiding=[gps,broken]", f"hydra.run.dir={tmp_path / 'o'}"], tmp_path, broken_site)
    assert proc.returncode == 2
    errors = [line for line in proc.stderr.splitlines() if line.startswith("quadest: error:")]
    assert len(errors) == 1 and "'broken = no_such_module_xyz:Sensor' of fake-sensors failed to import" in errors[0]
    assert "Traceback" not in proc.stderr


@pytest.mark.slow
def test_broken_sensor_plugins_do_not_stop_other_runs(broken_site, tmp_path):
    args = ["model=ins", "model.aiding=[gps]", "estimator=[mekf]", *SHORT]
    proc = quadest([*args, f"hydra.run.dir={tmp_path / 'o'}"], tmp_path, broken_site)
    assert proc.returncode == 0, proc.stderr
    assert "collides with the built-in sensor 'gps'" in proc.stderr
    assert proc.stderr.count("quadest: warning: sensor plugin") == 4


@pytest.mark.slow
def test_in_the_repository_a_model_and_a_sensor_are_two_files_each(tmp_path):
    """On a copy of ``src/`` and ``conf/``, the pendulum's module and YAML dropped into
    ``simulation/`` and ``conf/model/``, the rangefinder's into ``sensors/`` and
    ``conf/sensor/rangefinder/``, and nothing else edited: both run (docs/models.md,
    docs/sensors.md, "Where the two files go")."""
    root = PLUGINS.parents[1]
    for folder in ("src", "conf"):
        shutil.copytree(root / folder, tmp_path / folder, ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copy(PLUGINS / "pendulum_model.py", tmp_path / "src" / "quadest" / "simulation" / "pendulum_data.py")
    shutil.copy(PLUGINS / "conf" / "model" / "pendulum.yaml", tmp_path / "conf" / "model")
    shutil.copy(PLUGINS / "rangefinder_sensor.py", tmp_path / "src" / "quadest" / "sensors" / "rangefinder.py")
    shutil.copytree(PLUGINS / "conf" / "sensor" / "rangefinder", tmp_path / "conf" / "sensor" / "rangefinder")
    env = {**os.environ, "PYTHONPATH": str(tmp_path / "src")}
    runs = {
        "pendulum": ["model=pendulum", "estimator=[ekf]"],
        "rangefinder": ["model=ins", "model.aiding=[gps,rangefinder]", "+sensor/rangefinder=lidar_lite"],
    }
    runs["rangefinder"].append("estimator=[mekf]")
    for name, args in runs.items():
        out = tmp_path / name
        proc = subprocess.run(
            [sys.executable, "-m", "quadest.app.cli", *args, *SHORT, f"hydra.run.dir={out}"],
            cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600,
        )  # fmt: skip
        assert proc.returncode == 0, proc.stderr
        table = pd.read_csv(out / "metrics.csv")
        assert not table["diverged"].any()
    assert "rangefinder" in proc.stdout and set(table["aiding"]) == {"gps+rangefinder"}
