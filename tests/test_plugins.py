"""The estimator plugin contract: conformance of every built-in, the CKF example, config-only
plugins, an external package installed beside quadest, and the errors a plugin author meets."""

from __future__ import annotations

import dataclasses
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from helpers import compose_config, compose_settings, random_spd, run_filter, simulate, smooth_model
from quadest.app.job import run_job
from quadest.conformance import check_estimator, linear_gaussian_problem
from quadest.estimators.base import PerRunAdapter
from quadest.estimators.cubature import CKF
from quadest.estimators.filterpy_ukf import FilterpyUKF
from quadest.estimators.params import Range, parameter_problem
from quadest.estimators.registry import EstimatorSpec, builtin_estimators, make_estimator
from quadest.models.attitude import AttitudeFilterModel
from quadest.models.base import FilterModel
from quadest.simulation.quadrotor_data import build_quadrotor_data
from target_plugin import Crashes, LinearizedKF

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "quadest-iekf"
ANCHORS = "quadest.estimators.ahrs_anchors"

# Estimators with nothing to refuse, each with the reason; a new estimator is not added here
# without one.
NO_BAD_PARAMETERS = {
    "ekf": "its Params declares no parameter",
    "hckf": "its one parameter, the flag augmented, declares no range or choices",
}
# An invalid value the filter refuses although no range declares it.
CHECKED_FLAGS = {"mekf": [{"reset_jacobian": "yes"}]}


def outside(rng: Range) -> list[float]:
    """The values nearest each declared bound on its wrong side, a fraction for an integer, and a
    non-finite value when nothing else is excluded."""
    values = [b for b in (rng.gt, rng.lt) if b is not None]
    if rng.ge is not None:
        values.append(rng.ge - 1 if rng.integer else math.nextafter(rng.ge, -math.inf))
    if rng.le is not None:
        values.append(rng.le + 1 if rng.integer else math.nextafter(rng.le, math.inf))
    if rng.integer:
        values.append(next((b for b in (rng.ge, rng.gt) if b is not None), 0) + 1.5)
    return values or [math.nan]


def model_for(spec: EstimatorSpec) -> FilterModel:
    if spec.cls.__module__ == ANCHORS:
        return AttitudeFilterModel(0.01, [0.0, 0.0, 9.81], [21.5, 0.0, 43.1], 1e-6 * np.eye(9), np.eye(3), np.eye(3))
    return linear_gaussian_problem()[0]


def bad_parameters(spec: EstimatorSpec) -> list[dict]:
    """Values the declarations of ``spec.params`` forbid, kept only if ``parameter_problem``
    refuses them: each ranged field just outside each bound, a word for each other field (an
    unknown choice option, a malformed initial range) and the UT's n + κ ≤ 0; then the checked
    flags."""
    n = model_for(spec).n
    candidates = []
    for f in dataclasses.fields(spec.params):
        rng = f.metadata.get("range")
        candidates += [{f.name: value} for value in outside(rng)] if rng else [{f.name: "no_such_option"}]
    if {"alpha", "kappa"} <= set(spec.params.__dataclass_fields__):
        candidates.append({"alpha": 1.0, "kappa": -n - 1.0})
    return [bad for bad in candidates if parameter_problem(spec.params, bad, n)] + CHECKED_FLAGS.get(spec.name, [])


@pytest.mark.parametrize("name", sorted(builtin_estimators()))
def test_every_builtin_estimator_passes_conformance(name):
    spec = builtin_estimators()[name]
    if spec.cls.__module__ == ANCHORS:
        pytest.skip("an ahrs anchor needs the attitude model, not a linear one: tests/test_ahrs_anchors.py")
    ut = "alpha" in {f for f in spec.params.__dataclass_fields__}
    gaussian = "random" not in spec.cls.capabilities  # a particle filter only approaches the Kalman filter
    params = {"alpha": 0.5} if ut else {}
    if "huber_threshold" in spec.params.__dataclass_fields__:
        params["huber_threshold"] = 1e12  # a Huber filter is the Kalman filter only as γ → ∞ (test_robust.py)
    check_estimator(spec.cls, params=params, bad_params=bad_parameters(spec), gaussian=gaussian)


@pytest.mark.parametrize("name", sorted(builtin_estimators()))
def test_every_builtin_estimator_is_given_bad_parameters(name):
    """No estimator escapes the bad-parameter checks with an empty list; an exemption must hold."""
    bad = bad_parameters(builtin_estimators()[name])
    if name in NO_BAD_PARAMETERS:
        assert not bad, f"{name} is exempt ({NO_BAD_PARAMETERS[name]}) but declares {bad} invalid"
    else:
        assert bad, f"{name}: no declared range, choice or checked flag gives a bad parameter; add one or exempt it"


def bad_parameter_cases() -> list:
    return [
        pytest.param(name, bad, id=f"{name}-{'-'.join(f'{k}={v}' for k, v in bad.items())}")
        for name, spec in sorted(builtin_estimators().items())
        for bad in bad_parameters(spec)
    ]


@pytest.mark.parametrize(("name", "bad"), bad_parameter_cases())
def test_bad_parameters_are_refused_at_construction_with_a_message_naming_them(name, bad):
    """Every declared range is enforced by the estimator base class itself, not only by the
    pre-run validation; this also covers the ahrs anchors and holds the message to the key."""
    spec = builtin_estimators()[name]
    with pytest.raises(ValueError, match="|".join(bad)):
        make_estimator(spec.cls, model_for(spec), bad)


def test_conformance_catches_a_wrong_filter():
    class Overconfident(LinearizedKF):
        def update(self, z, u):
            super().update(z, u)
            self.P = 0.5 * self.P

    with pytest.raises(AssertionError, match="differs from the Kalman filter"):
        check_estimator(Overconfident)
    with pytest.raises(AssertionError, match="were accepted"):
        check_estimator(LinearizedKF, bad_params=[{"inflation": 2.0}])
    check_estimator(LinearizedKF, bad_params=[{"inflation": 0.5}])


def test_ckf_equals_ukf_with_alpha_one_beta_zero_kappa_zero():
    """Arasaratnam & Haykin 2009: the 3rd-degree CKF is the UKF with α = 1, β = 0, κ = 0."""
    model = smooth_model(21)
    rng = np.random.default_rng(21)
    P0 = random_spd(rng, 4, 0.5)[None]
    x, u, z = simulate(model, rng.standard_normal((1, 4)), 100, 21)
    a = run_filter(CKF(model), model, x[:, 0], P0, u, z)
    b = run_filter(PerRunAdapter(model, FilterpyUKF, alpha=1.0, beta=0.0, kappa=0.0), model, x[:, 0], P0, u, z)
    for got, ref in zip(a, b, strict=True):
        assert np.abs(got - ref).max() / np.abs(ref).max() <= 1e-9


def test_ckf_equals_ukf_on_the_quadrotor():
    data = build_quadrotor_data(compose_settings(["runs=2", "duration=1.0", "model.formulation=augmented"]))
    m = data.model
    u = np.stack([m.filter_input(data.inputs[:, k], data.companion_truth[:, k]) for k in range(data.time.size)], 1)
    P0 = np.broadcast_to(data.P0, (2, m.n, m.n))
    a = run_filter(CKF(m), m, data.x0, P0, u, data.measurements)
    b = run_filter(PerRunAdapter(m, FilterpyUKF, alpha=1.0, beta=0.0, kappa=0.0), m, data.x0, P0, u, data.measurements)
    for got, ref in zip(a, b, strict=True):
        assert np.abs(got - ref).max() / np.abs(ref).max() <= 1e-9


def job_table(tmp_path: Path, overrides: list[str]) -> pd.DataFrame:
    cfg = compose_config(["runs=3", "duration=0.3", "progress=false", "output.figures=false", "workers=1", *overrides])
    run_job(cfg, tmp_path / "job")
    return pd.read_csv(tmp_path / "job" / "metrics.csv")


def test_config_only_plugin_by_target(tmp_path):
    table = job_table(
        tmp_path,
        ["estimator=[srukf]", "+estimator.mine._target_=target_plugin.LinearizedKF", "+estimator.mine.inflation=1.0"],
    )
    assert set(table["estimator"]) == {"srukf", "mine"}
    assert not table["diverged"].any()


@pytest.mark.parametrize(
    ("target", "extra", "expected"),
    [
        ("no_such_module.Filter", [], "an importable class"),
        ("target_plugin.NotAnEstimator", [], "must subclass"),
        ("target_plugin.LinearizedKF", ["+estimator.mine.inflaton=1.0"], "takes ['inflation']"),
    ],
)
def test_config_only_plugin_errors_name_the_problem(tmp_path, target, extra, expected):
    from quadest.errors import ConfigError

    with pytest.raises(ConfigError, match=r"estimator\.mine") as info:
        job_table(tmp_path, ["estimator=[srukf]", f"+estimator.mine._target_={target}", *extra])
    assert expected in str(info.value)
    assert "\n" not in str(info.value)


def test_plugin_that_raises_marks_only_its_run(tmp_path):
    Crashes.created = 0
    table = job_table(tmp_path, ["estimator=[srukf]", "+estimator.boom._target_=target_plugin.Crashes"])
    boom = table[(table["estimator"] == "boom") & (table["state"] == "vx")]
    assert boom["diverged"].tolist() == [False, True, False]
    assert "RuntimeError: plugin exploded" in boom["failure_reason"].iloc[1]
    assert not table[table["estimator"] == "srukf"]["diverged"].any()


def quadest(args: list[str], cwd: Path, pythonpath: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(pythonpath), os.environ.get("PYTHONPATH", "")])}
    return subprocess.run(
        [sys.executable, "-m", "quadest.app.cli", *args], cwd=cwd, env=env, capture_output=True, text=True, timeout=300
    )


@pytest.fixture(scope="module")
def installed_example(tmp_path_factory) -> Path:
    """The example package installed into a private directory (put on PYTHONPATH), so the test
    environment itself is not modified."""
    target = tmp_path_factory.mktemp("site")
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "install",
            "--quiet",
            "--no-deps",
            "--no-build-isolation",
            "--target",
            str(target),
            str(EXAMPLE),
        ],
        check=True,
        capture_output=True,
        text=True,
    )
    return target


@pytest.mark.slow
def test_external_package_runs_a_comparison(installed_example, tmp_path):
    out = tmp_path / "run"
    proc = quadest(
        [
            "estimator=[srukf,single_run_iekf]",
            "runs=2",
            "duration=0.5",
            "progress=false",
            "output.figures=false",
            "estimator.single_run_iekf.iterations=2",
            f"hydra.run.dir={out}",
        ],
        tmp_path,
        installed_example,
    )
    assert proc.returncode == 0, proc.stderr
    table = pd.read_csv(out / "metrics.csv")
    assert set(table["estimator"]) == {"srukf", "single_run_iekf"}
    assert not table["diverged"].any()


def test_external_package_passes_conformance(installed_example, tmp_path):
    code = (
        "from quadest.conformance import check_estimator\n"
        "from quadest_iekf.filter import IteratedEKF\n"
        "check_estimator(IteratedEKF, bad_params=[{'iterations': 0}])\n"
    )
    env = {**os.environ, "PYTHONPATH": str(installed_example)}
    proc = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr


@pytest.fixture(scope="module")
def broken_plugins(tmp_path_factory) -> Path:
    """A fake installed distribution whose entry points collide, fail to import, or break the
    contract."""
    site = tmp_path_factory.mktemp("broken")
    info = site / "fake_plugins-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: fake-plugins\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(
        "[quadest.estimators]\nsrukf = json:JSONDecoder\nbroken = no_such_module_xyz:Filter\n"
        "notafilter = json:JSONDecoder\n"
    )
    return site


@pytest.mark.parametrize(
    ("name", "expected"),
    [("broken", "failed to import: ModuleNotFoundError"), ("notafilter", "does not meet the contract")],
)
def test_selecting_a_broken_plugin_gives_one_line(broken_plugins, tmp_path, name, expected):
    proc = quadest([f"estimator=[{name}]", f"hydra.run.dir={tmp_path / 'o'}"], tmp_path, broken_plugins)
    assert proc.returncode == 2
    errors = [ln for ln in proc.stderr.splitlines() if ln.startswith("quadest: error:")]
    assert len(errors) == 1 and f"'{name} = " in errors[0] and "fake-plugins" in errors[0] and expected in errors[0]
    assert "Traceback" not in proc.stderr


@pytest.mark.slow
def test_broken_plugins_do_not_stop_other_runs(broken_plugins, tmp_path):
    proc = quadest(
        [
            "estimator=[srukf]",
            "runs=1",
            "duration=0.1",
            "progress=false",
            "output.figures=false",
            f"hydra.run.dir={tmp_path / 'o'}",
        ],
        tmp_path,
        broken_plugins,
    )
    assert proc.returncode == 0, proc.stderr
    assert "collides with the built-in estimator 'srukf'" in proc.stderr
    assert proc.stderr.count("quadest: warning:") == 3
