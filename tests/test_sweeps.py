"""Sweeps: experiments compose, a real multirun aggregates, launchers agree, and aggregation
survives failed, unfinished and missing jobs."""

from __future__ import annotations

import dataclasses
import itertools
import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml
from hydra import compose, initialize_config_dir
from hydra.core.global_hydra import GlobalHydra
from hydra.core.override_parser.overrides_parser import OverridesParser
from omegaconf import OmegaConf

from quadest.aggregate.cli import main as aggregate_main
from quadest.aggregate.report import aggregate
from quadest.aggregate.sweep import expected_jobs
from quadest.app.cli import one_way
from quadest.app.schema import register_schemas
from quadest.app.settings import data_settings
from quadest.app.validate import validate
from quadest.conformance import check_sigma_point_moments
from quadest.estimators.registry import resolve
from quadest.models.quadrotor_config import triad_spec
from quadest.montecarlo.streams import run_seed_sequences, run_streams
from quadest.simulation.registry import build_data

ROOT = Path(__file__).resolve().parents[1]
EXPERIMENTS = ROOT / "experiments"

MINI = """
defaults:
  - config
  - override /estimator: [ukf, srukf]
  - override hydra/launcher: quadest_joblib
  - _self_
runs: 2
duration: 0.3
workers: 1
progress: false
output: {saved_runs: 1, figures: false}
cache: {enabled: false}  # each launcher computes: the comparison must not read the other's results
sweep: {alpha: 0.5, beta: 2.0, kappa: 0.0}
estimator:
  ukf: {alpha: "${sweep.alpha}", beta: "${sweep.beta}", kappa: "${sweep.kappa}"}
  srukf: {alpha: "${sweep.alpha}", beta: "${sweep.beta}", kappa: "${sweep.kappa}"}
hydra:
  mode: MULTIRUN
  sweep: {subdir: "${hydra.job.num}"}
  sweeper:
    params:
      sweep.alpha: 0.5,1.0
      sweep.beta: 0.0,2.0
  callbacks:
    aggregate: {_target_: quadest.app.callbacks.AggregateCallback}
"""


@pytest.mark.parametrize("name", sorted(p.stem for p in EXPERIMENTS.glob("*.yaml")))
@pytest.mark.slow
def test_every_experiment_file_composes_and_validates(name):
    """The task config is validated as the CLI sees it (without the ``hydra`` node)."""
    validate(compose_experiment(name))
    cfg = compose_experiment(name, hydra=True)
    assert "multirun" in cfg.hydra.sweep.dir and name in cfg.hydra.sweep.dir


def compose_experiment(name: str, overrides: list[str] | None = None, hydra: bool = False):
    """The config of ``quadest experiment=NAME [overrides]``: the file ``experiments/NAME.yaml`` as
    the primary config (``quadest.app.cli.one_way``)."""
    argv, primary = one_way([f"experiment={name}", *(overrides or [])])
    assert primary == EXPERIMENTS / f"{name}.yaml"
    register_schemas()
    GlobalHydra.instance().clear()
    with initialize_config_dir(config_dir=str(primary.parent), version_base="1.3"):
        cfg = compose(config_name=primary.stem, overrides=argv[4:], return_hydra_config=hydra)
    GlobalHydra.instance().clear()
    return cfg


def sweep_cells(name: str) -> list[dict[str, str]]:
    """Every cell of an experiment's sweep, ``{key: value}``, parsed by Hydra's own override
    parser (so ranges and choices expand as the sweeper expands them)."""
    params = compose_experiment(name, hydra=True).hydra.sweeper.get("params") or {}
    parser = OverridesParser.create()
    axes = [
        [(key, value) for value in parser.parse_override(f"{key}={spec}").sweep_string_iterator()]
        for key, spec in params.items()
    ]
    return [dict(cell) for cell in itertools.product(*axes)]


UT_KEYS = ("sweep.alpha", "sweep.beta", "sweep.kappa")
PROBE_N = 4  # state dimension of quadest.conformance's quadratic probe


def _names_sweep_key(node, field: str, key: str) -> bool:
    """Whether the estimator's unresolved ``node`` takes ``field`` from the sweep key ``key``."""
    return f"${{{key}}}" in str(OmegaConf.to_container(node, resolve=False).get(field, ""))


def check_ut_keys(name: str, cell: dict[str, str], cfg) -> None:
    """Every selected estimator that takes its UT parameters from the sweep (``${sweep.alpha}``
    ...) receives the cell's (α, β, κ) and behaves as that UT on the quadratic probe of
    ``quadest.conformance`` (its weights W0(c) hold β); at least one does. A UT filter that keeps its
    own parameters (a baseline run once per sensor level, ``sweep_ut_grid``'s UKF) is not swept.
    The probe has n = 4, so a κ ≤ −4 (the UT grid's −6 for its n = 9 model) is checked by value only."""
    swept = tuple(float(cell[k]) for k in UT_KEYS)
    ut_filters = 0
    for label, node in cfg.estimator.items():
        cls, params = resolve(label, OmegaConf.to_container(node, resolve=True))
        if not {"alpha", "beta", "kappa"} <= {f.name for f in dataclasses.fields(cls.Params)}:
            continue
        if not any(_names_sweep_key(node, f, k) for f, k in zip(("alpha", "beta", "kappa"), UT_KEYS, strict=True)):
            continue
        ut_filters += 1
        got = tuple(float(params.get(k, "nan")) for k in ("alpha", "beta", "kappa"))
        assert got == swept, f"{name} {cell}: estimator.{label} gets (alpha, beta, kappa) = {got}"
        if PROBE_N + swept[2] > 0:  # the probe's points exist (n + κ > 0 at its n = 4); at κ = −6 only the values
            check_sigma_point_moments(cls, params, ut=swept)
    assert ut_filters, f"{name} {cell}: sweeps UT parameters but selects no UT filter"


def _measurements_at(cfg, scale: float):
    """Data of ``cfg`` (one short run) with ``sensor.error_scale`` set to ``scale``."""
    cfg = cfg.copy()
    cfg.sensor.error_scale = scale
    return build_data(data_settings(cfg))


def check_sensor_keys(name: str, cell: dict[str, str], cfg) -> None:
    """The grade named by ``sensor`` and the ``sensor.error_scale`` reach both sides: the filter
    model's R is the formula of quadest.models.quadrotor_config applied to the grade's YAML file
    read directly, times scale²; the measurements' error (measurement minus the error-free one,
    error_scale = 0) is exactly ``scale`` times the error at scale 1 (the same draws, scaled)."""
    grade = cell.get("sensor", cfg.sensor.name)
    scale = float(cell.get("sensor.error_scale", cfg.sensor.error_scale))
    assert cfg.sensor.name == grade and float(cfg.sensor.error_scale) == scale
    spec = OmegaConf.load(ROOT / "conf" / "sensor" / f"{grade}.yaml")
    T, duration = float(cfg.sample_period), float(cfg.duration)
    data = build_data(data_settings(cfg))

    def var(triad) -> float:
        white, walk = scale * triad.get("white_noise", 0.0), scale * triad.get("bias_random_walk", 0.0)
        return white**2 / T + walk**2 * duration / 2.0

    R = float(cfg.model.measurement_noise_inflation) * np.diag([var(spec.accel)] * 3 + [var(spec.gyro)] * 3)
    np.testing.assert_allclose(data.model.R, R, rtol=1e-12, err_msg=f"{name} {cell}: R")
    exact = _measurements_at(cfg, 0.0).measurements
    unit = _measurements_at(cfg, 1.0).measurements - exact
    assert np.abs(unit).max() > 0
    np.testing.assert_allclose(data.measurements - exact, scale * unit, rtol=1e-9, atol=1e-12 * np.abs(exact).max())


def check_contamination_keys(name: str, cell: dict[str, str], cfg) -> None:
    """``sweep.epsilon`` and ``sweep.variance_factor`` reach both triads' noise laws and the data:
    the measurements are the Gaussian-law data plus ``σ n (s − 1)``, with the normal draws ``n``
    and the outlier multipliers ``s`` redrawn here from each run's noise stream (walk increments,
    then ``n``, then the uniforms that pick the outliers); the filters' R is unchanged."""
    eps, factor = float(cell["sweep.epsilon"]), float(cell["sweep.variance_factor"])
    for triad in ("accel", "gyro"):
        law = cfg.sensor[triad].noise_law
        assert (law.kind, float(law.epsilon), float(law.variance_factor)) == ("contaminated", eps, factor)
    data = build_data(data_settings(cfg))
    gaussian = cfg.copy()
    for triad in ("accel", "gyro"):
        gaussian.sensor[triad].noise_law.kind = "gaussian"
    base = build_data(data_settings(gaussian))
    np.testing.assert_array_equal(data.model.R, base.model.R)
    T, K1 = float(cfg.sample_period), data.time.size
    streams = run_streams(int(cfg.seed), int(cfg.runs))
    expected = base.measurements.copy()
    for cols, triad in ((slice(0, 3), "accel"), (slice(3, 6), "gyro")):
        sigma = triad_spec(cfg.sensor[triad], float(cfg.sensor.error_scale)).white_noise_std(T)
        for i, rng in enumerate(streams[f"{triad}_noise"]):
            rng.standard_normal((K1, 3))
            n = rng.standard_normal((K1, 3))
            s = np.where(rng.random((K1, 3)) < eps, np.sqrt(factor), 1.0)
            expected[i, :, cols] += sigma * n * (s - 1.0)
    np.testing.assert_allclose(data.measurements, expected, rtol=1e-12, atol=1e-12, err_msg=f"{name} {cell}")


def check_process_noise_key(name: str, cell: dict[str, str], cfg) -> None:
    """``model.Q`` of seed 001's rate model reaches both sides: every filter's Q is ``Q I₃``, and
    the truth's increments ``x_k − f(x_{k−1}, Ω_{k−1})`` are √Q times the run's ``process`` stream
    draws (the truth is driven by the swept noise, not only the filters' assumption)."""
    q = float(cell["model.Q"])
    data = build_data(data_settings(cfg))
    np.testing.assert_array_equal(data.model.Q, q * np.eye(3))
    x, u = data.truth, data.inputs
    increments = np.stack(
        [x[:, k] - data.model.f(x[:, k - 1][:, None], u[:, k - 1])[:, 0] for k in range(1, x.shape[1])], 1
    )
    draws = np.stack(
        [rng.standard_normal((x.shape[1], 3)) for rng in run_streams(int(cfg.seed), int(cfg.runs))["process"]]
    )
    np.testing.assert_allclose(increments, np.sqrt(q) * draws[:, 1:], rtol=0, atol=1e-12, err_msg=f"{name} {cell}")


def check_huber_threshold_key(name: str, cell: dict[str, str], cfg) -> None:
    """``sweep.gamma`` reaches the Huber threshold of every estimator that names it, and only those
    (the plain filters of the comparison keep theirs); at least one is swept."""
    gamma, swept = float(cell["sweep.gamma"]), 0
    for label, node in cfg.estimator.items():
        _, params = resolve(label, OmegaConf.to_container(node, resolve=True))
        if _names_sweep_key(node, "huber_threshold", "sweep.gamma"):
            swept += 1
            assert float(params["huber_threshold"]) == gamma, f"{name} {cell}: estimator.{label}"
    assert swept, f"{name} {cell}: sweeps gamma but no estimator takes it"


def _error_offsets(cfg):
    """(B, 15) offsets of the initial estimates from the truth, in the error state, and P0."""
    data = build_data(data_settings(cfg))
    return data.model.boxminus(data.x0, data.truth[:, 0]), data.P0


def check_initial_error_key(name: str, cell: dict[str, str], cfg) -> None:
    """``sweep.initial_error`` selects a level whose one-sigma attitude and position errors become
    the diagonal of P0 and scale the initial estimates' offsets from the truth: the same draws as
    at the first level, times the ratio of the levels (error state: attitude, position, velocity,
    gyro bias, accel bias, three each)."""
    level = cfg.sweep.levels[cell["sweep.initial_error"]]
    first = next(iter(cfg.sweep.levels))
    base_cfg = compose_experiment(name, [f"sweep.initial_error={first}", "runs=1", "duration=0.05"])
    offsets, P0 = _error_offsets(cfg)
    base_offsets, base_P0 = _error_offsets(base_cfg)
    for block, key in ((slice(0, 3), "attitude"), (slice(3, 6), "position")):
        np.testing.assert_allclose(np.diag(P0)[block], float(level[key]) ** 2, rtol=1e-12)
        ratio = float(level[key]) / float(cfg.sweep.levels[first][key])
        np.testing.assert_allclose(offsets[:, block], ratio * base_offsets[:, block], rtol=1e-9, atol=1e-12)
    np.testing.assert_array_equal(np.diag(P0)[6:], np.diag(base_P0)[6:])


def check_vision_noise_key(name: str, cell: dict[str, str], cfg) -> None:
    """``sensor.vision.los_noise`` reaches both sides: the camera's R in the filters is σ² I,
    and its measurement error (measurement minus h of the truth) is σ times the error at σ = 1e-3
    (the same draws, scaled; the contaminated law multiplies each draw by the same factor)."""
    sigma = float(cell["sensor.vision.los_noise"])

    def error(c):
        data = build_data(data_settings(c))
        vision = data.model.sensors["vision"]
        exact = np.stack([vision.h(data.truth[:, k], data.inputs[:, k]) for k in range(data.time.size)], 1)
        return data, data.sensors["vision"].values - exact

    data, err = error(cfg)
    _, unit = error(compose_experiment(name, ["sensor.vision.los_noise=1e-3", "runs=1", "duration=0.05"]))
    np.testing.assert_allclose(data.model.sensors["vision"].R, sigma**2 * np.eye(err.shape[-1]), rtol=1e-12)
    seen = data.sensors["vision"].available
    assert seen.any() and np.abs(err[:, seen]).max() > 0
    np.testing.assert_allclose(err[:, seen], sigma / 1e-3 * unit[:, seen], rtol=1e-7, atol=1e-12)


def check_seed_key(name: str, cell: dict[str, str], cfg) -> None:
    """``seed`` reaches the run streams: the estimators' seed sequences are those of
    :func:`run_seed_sequences` for the swept seed (entropy and spawn key)."""
    seed = int(cell["seed"])
    assert int(cfg.seed) == seed
    data = build_data(data_settings(cfg))
    expected = run_seed_sequences(seed, int(cfg.runs))["estimator"]
    got = [(s.entropy, s.spawn_key) for s in data.estimator_seeds]
    assert got == [(s.entropy, s.spawn_key) for s in expected], f"{name} {cell}"


KEY_CHECKS = {
    **dict.fromkeys(UT_KEYS, check_ut_keys),
    "sweep.epsilon": check_contamination_keys,
    "sweep.variance_factor": check_contamination_keys,
    "sensor": check_sensor_keys,
    "sensor.error_scale": check_sensor_keys,
    "model.Q": check_process_noise_key,
    "sweep.gamma": check_huber_threshold_key,
    "sweep.initial_error": check_initial_error_key,
    "sensor.vision.los_noise": check_vision_noise_key,
    "seed": check_seed_key,
}


@pytest.mark.parametrize("name", sorted(p.stem for p in EXPERIMENTS.glob("*.yaml")))
@pytest.mark.slow
def test_every_swept_key_reaches_what_it_names(name):
    """Composing is not enough: for each cell of each sweep, the swept values must arrive in the
    estimators (UT parameters) or in the model and measurements (sensor grade and error scale)."""
    cells = sweep_cells(name)
    unchecked = {key for cell in cells for key in cell} - set(KEY_CHECKS)
    assert not unchecked, f"{name}: no check says where {sorted(unchecked)} must arrive; add one to KEY_CHECKS"
    for check in dict.fromkeys(KEY_CHECKS[key] for cell in cells for key in cell):
        # a check runs once per distinct value of the keys it checks (the UT grid's 1000 cells
        # hold 250 distinct (alpha, beta, kappa) and 4 sensor levels)
        covered = [key for key, c in KEY_CHECKS.items() if c is check]
        distinct = {tuple((k, cell[k]) for k in covered if k in cell): cell for cell in cells}
        for cell in distinct.values():
            cfg = compose_experiment(name, [*(f"{k}={v}" for k, v in cell.items()), "runs=1", "duration=0.05"])
            check(name, cell, cfg)


def run_sweep(tmp: Path, launcher: str) -> Path:
    (tmp / "mini.yaml").write_text(MINI)
    out = tmp / f"sweep_{launcher}"
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "quadest.app.cli",
            "-cd",
            str(tmp),
            "-cn",
            "mini",
            f"hydra/launcher={launcher}",
            f"hydra.sweep.dir={out}",
            "runs=2",  # a command-line override named like a table column
        ],
        cwd=tmp,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "Aggregated:" in proc.stdout
    return out


@pytest.fixture(scope="module")
def sweeps(tmp_path_factory) -> dict[str, Path]:
    tmp = tmp_path_factory.mktemp("sweeps")
    return {launcher: run_sweep(tmp, launcher) for launcher in ("quadest_joblib", "basic")}


@pytest.mark.slow
def test_multirun_aggregate_has_the_expected_rows_and_columns(sweeps):
    out = sweeps["quadest_joblib"] / "aggregate"
    cells = pd.read_csv(out / "cells.csv")
    assert sorted(cells["job"].unique()) == [0, 1, 2, 3]
    assert len(cells) == 4 * 2 * (6 + 6)  # jobs × estimators × (filter states + companions)
    assert (cells["override.runs"] == 2).all() and (cells["runs"] == 2).all()
    for col in (
        "sweep.alpha",
        "sweep.beta",
        "estimator",
        "state",
        "rmse_mean",
        "rmse_std",
        "ci95_low",
        "ci95_high",
        "mse_mean",
        "diverged",
        "step_time_us",
        "pcrlb",
    ):
        assert col in cells.columns, col
    assert set(zip(cells["sweep.alpha"], cells["sweep.beta"], strict=True)) == {
        (0.5, 0.0),
        (0.5, 2.0),
        (1.0, 0.0),
        (1.0, 2.0),
    }
    for table in ("rmse", "best_cells", "divergence", "timing"):
        for ext in ("csv", "md", "tex"):
            assert (out / f"{table}.{ext}").is_file()
    assert len(pd.read_csv(out / "best_cells.csv")) == 2
    for fig in ("rmse_vs_alpha_srukf", "alpha_beta_heatmap_ukf", "rmse_bars"):
        assert (out / "figures" / f"{fig}.png").is_file() and (out / "figures" / f"{fig}.pdf").is_file()
    report = (out / "report.md").read_text()
    assert "commit:" in report and "ok: 4" in report


@pytest.mark.slow
def test_sweep_aggregate_collects_each_cells_paired_comparison(sweeps):
    """The aggregate's paired table is every cell's own paired_comparison.csv, tagged with the job
    and its swept values (Holm's family stays the cell), plus a one-row-per-pair summary."""
    root = sweeps["quadest_joblib"]
    paired = pd.read_csv(root / "aggregate" / "paired.csv")
    assert sorted(paired["job"].unique()) == [0, 1, 2, 3]
    for job in range(4):
        own = pd.read_csv(root / str(job) / "paired_comparison.csv")
        got = paired[paired["job"] == job].drop(columns=["job", "sweep.alpha", "sweep.beta", "override.runs"])
        pd.testing.assert_frame_equal(got.reset_index(drop=True), own, check_dtype=False)
    summary = pd.read_csv(root / "aggregate" / "paired_summary.csv")
    assert len(summary) == 4 * paired["pair"].nunique()
    assert "paired summary" in (root / "aggregate" / "report.md").read_text()


@pytest.mark.slow
def test_basic_and_joblib_launchers_give_identical_metrics(sweeps):
    a = pd.read_csv(sweeps["quadest_joblib"] / "aggregate" / "cells.csv").sort_values(["job", "estimator", "state"])
    b = pd.read_csv(sweeps["basic"] / "aggregate" / "cells.csv").sort_values(["job", "estimator", "state"])
    cols = ["rmse_mean", "rmse_std", "mse_mean", "pooled_rmse", "mean_nees", "mean_nis"]
    pd.testing.assert_frame_equal(a[cols].reset_index(drop=True), b[cols].reset_index(drop=True))


@pytest.mark.slow
def test_aggregation_reports_failed_unfinished_and_missing_jobs(sweeps, tmp_path):
    broken = tmp_path / "broken"
    shutil.copytree(sweeps["basic"], broken)
    shutil.rmtree(broken / "aggregate")
    (broken / "1" / "summary.json").write_text(json.dumps({"status": "failed", "error": "ConfigError: boom"}))
    (broken / "2" / "summary.json").unlink()  # killed halfway
    shutil.rmtree(broken / "3")  # never ran
    report = aggregate(broken).read_text()
    jobs = pd.read_csv(broken / "aggregate" / "jobs.csv")
    assert jobs["status"].tolist() == ["ok", "failed", "did not finish", "missing"]
    assert "ConfigError: boom" in report and "missing" in report and "did not finish" in report
    cells = pd.read_csv(broken / "aggregate" / "cells.csv")
    assert cells["job"].unique().tolist() == [0]
    assert (broken / "aggregate" / "rmse.md").is_file()


def test_aggregate_command_rejects_a_missing_folder(tmp_path, capsys):
    assert aggregate_main([str(tmp_path / "nope")]) == 2
    assert "is not a directory" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("params", "task", "expected"),
    [
        ({"a": "1,2,3", "b": "4,5"}, [], 6),
        ({"a": "1,2,3"}, ["b=7,8"], 6),
        ({"a": "1,2,3"}, ["a=9"], 1),
        ({"a": "1,2,3", "b": "4,5"}, ["a=9,10"], 4),
        ({"a": "1,2,3"}, ["c=[1,2]"], 3),
    ],
)
def test_expected_jobs_lets_the_command_line_replace_a_swept_key(tmp_path, params, task, expected):
    """Hydra's basic sweeper appends the command-line overrides to the sweeper params and the last
    one of a key wins, so ``a=9`` on the command line shrinks a 3-value axis to one job."""
    (tmp_path / "multirun.yaml").write_text(
        yaml.safe_dump({"hydra": {"sweeper": {"params": params}, "overrides": {"task": task}}})
    )
    assert expected_jobs(tmp_path) == expected
