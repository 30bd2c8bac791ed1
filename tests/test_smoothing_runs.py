"""Smoothers inside a run (:func:`quadest.runner.run_estimator` with a smoother): the smoothed
estimates are scored like a filter's, against the same truth, as their own result.

Independent references: the linear model's smoothed estimates equal filterpy's RTS smoother run
by hand on the same data; the smoothed NEES of a consistent smoother sits near its degrees of
freedom; on the manifold models (the MEKF with its reset) smoothing lowers the error the filter
leaves; the fused compiled SR-UKF records the same smoother steps as the family's numpy path.
"""

from __future__ import annotations

import pickle
import subprocess
import sys

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter

from helpers import compose_config, compose_settings
from quadest.app.settings import data_settings
from quadest.errors import ConfigError
from quadest.estimators.error_state_ekf import ErrorStateEKF
from quadest.estimators.registry import build_estimator, resolve
from quadest.estimators.smoother_settings import SmootherSettings, smoother_settings
from quadest.estimators.smoothing import SmootherStep
from quadest.runner import run_estimator, smoother_seed
from quadest.simulation.registry import build_data

LINEAR = ["model=linear", "sample_period=0.1", "duration=4.0", "progress=false"]


def run(overrides: list[str], label: str, smoother: SmootherSettings, saved_runs: int = 2):
    cfg = compose_config(overrides)
    data = build_data(data_settings(cfg))
    node = cfg.estimator[label]
    est = build_estimator(label, node, data.model)
    return data, run_estimator(label, est, data, 1e6, saved_runs, smoother=smoother)


def test_smoothed_estimates_of_a_run_are_filterpys_rts_smoother_on_the_linear_model():
    data, result = run([*LINEAR, "runs=2", "estimator=[mekf]"], "mekf", SmootherSettings("fixed_interval"))
    smoothed = result.smoothed
    assert smoothed.name == "mekf+smoothed"
    model = data.model
    for run_index in range(2):
        kf = KalmanFilter(dim_x=model.n, dim_z=model.m)
        kf.x, kf.P = data.x0[run_index].copy(), np.array(data.P0, dtype=float).copy()
        kf.F, kf.H, kf.Q, kf.R = model.A, model.C, model.Q, model.R
        means, covs, _, _ = kf.batch_filter(list(data.measurements[run_index, 1:]))
        xs, Ps, _, _ = kf.rts_smoother(means, covs)
        np.testing.assert_allclose(result.saved["estimate"][run_index, 1:], means, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(smoothed.saved["estimate"][run_index, 1:], xs, rtol=1e-9, atol=1e-9)
        std = np.sqrt(np.diagonal(Ps, axis1=-2, axis2=-1))
        np.testing.assert_allclose(smoothed.saved["std"][run_index, 1:], std, rtol=1e-9, atol=1e-12)


def test_the_smoother_is_consistent_and_better_than_the_filter_on_the_linear_model():
    """The runs' mean NEES (independent between runs) average to the degrees of freedom within four
    standard errors (measured: 3.61 against 4, 2.4 standard errors; the filter's is 3.72), and the
    RMSE is below the filter's in every state (the linear model is where the smoother is exact).
    A smoothed covariance off by 20 % moves the NEES by about 0.8, five standard errors."""
    runs = 60
    _, result = run([*LINEAR, f"runs={runs}", "estimator=[srckf]"], "srckf", SmootherSettings("fixed_interval"))
    smoothed = result.smoothed
    per_run = smoothed.nees_sum / smoothed.nees_steps
    assert abs(per_run.mean() - 4) < 4.0 * per_run.std(ddof=1) / np.sqrt(runs), per_run.mean()
    assert np.all(np.nanmean(smoothed.rmse, axis=0) < np.nanmean(result.rmse, axis=0))


@pytest.mark.parametrize("kind", ["fixed_interval", "fixed_lag"])
@pytest.mark.parametrize("model,label", [("attitude", "mekf"), ("ins", "mekf"), ("ins", "srukf")])
@pytest.mark.slow
def test_smoothing_a_manifold_filter_lowers_its_error(model, label, kind):
    _, result = run(
        [f"model={model}", "runs=4", "duration=3.0", f"estimator=[{label}]", "progress=false"],
        label,
        SmootherSettings(kind, lag=50),
    )
    smoothed = result.smoothed
    assert not smoothed.diverged.any()
    filtered_total = np.nansum(np.nanmean(result.rmse**2, axis=0))
    smoothed_total = np.nansum(np.nanmean(smoothed.rmse**2, axis=0))
    assert smoothed_total < filtered_total


@pytest.mark.slow
def test_ffbsi_in_a_run_repeats_and_improves_on_the_filter():
    overrides = [
        "model=ungm",
        "runs=3",
        "duration=10",
        "estimator=[pf]",
        "estimator.pf.particles=300",
        "progress=false",
    ]
    settings = SmootherSettings("fixed_interval", trajectories=50)
    _, first = run(overrides, "pf", settings)
    _, again = run(overrides, "pf", settings)
    np.testing.assert_array_equal(first.smoothed.sq_error_sum, again.smoothed.sq_error_sum)
    assert first.smoothed.name == "pf+smoothed"
    assert np.nanmean(first.smoothed.rmse) < np.nanmean(first.rmse)


def test_smoother_keys_are_checked_with_one_line_errors():
    cfg = compose_config(["model=linear", "estimator=[ekf,pf,srukf]"])
    for label, node_overrides, key in [
        ("srukf", {"smoother": "backward"}, "estimator.srukf.smoother"),
        ("srukf", {"smoother": "fixed_lag", "smoother_lag": 0}, "estimator.srukf.smoother_lag"),
        ("pf", {"smoother": "fixed_interval", "smoother_trajectories": 0}, "estimator.pf.smoother_trajectories"),
        ("pf", {"smoother": "fixed_lag"}, "estimator.pf.smoother"),
    ]:
        node = {**cfg.estimator[label], **node_overrides}
        cls, _ = resolve(label, node)
        with pytest.raises(ConfigError, match=key.replace(".", r"\.")):
            smoother_settings(label, node, cls)

    class WithoutSteps:  # a plugin filter that records no smoother steps (as the ahrs anchors)
        capabilities = frozenset({"innovation"})

    with pytest.raises(ConfigError, match=r"estimator\.plugin\.smoother.*keeps no smoother steps"):
        smoother_settings("plugin", {"smoother": "fixed_interval"}, WithoutSteps)
    node = {**cfg.estimator["srukf"], "smoother": "fixed_lag", "smoother_lag": 5}
    assert smoother_settings("srukf", node, resolve("srukf", node)[0]) == SmootherSettings("fixed_lag", 5, 100)
    assert smoother_settings("srukf", cfg.estimator["srukf"], resolve("srukf", cfg.estimator["srukf"])[0]) is None


def test_the_fused_srukf_records_the_smoother_steps_of_the_family_path(monkeypatch):
    """The compiled fused SR-UKF (quadrotor) and the numpy family path agree to round-off, and so
    do their smoothed estimates."""
    overrides = ["runs=2", "duration=0.5", "estimator=[srukf]", "progress=false"]
    results = {}
    for backend in ("numba", "numpy"):
        monkeypatch.setenv("QUADEST_KERNELS", backend)
        results[backend] = run(overrides, "srukf", SmootherSettings("fixed_interval"))[1]
    fused, family = results["numba"].smoothed, results["numpy"].smoothed
    np.testing.assert_allclose(fused.saved["estimate"], family.saved["estimate"], rtol=1e-9, atol=1e-10)
    np.testing.assert_allclose(fused.saved["std"], family.saved["std"], rtol=1e-7, atol=1e-12)


def test_a_run_the_filter_lost_is_left_out_of_the_smoothed_result():
    cfg = compose_config([*LINEAR, "runs=3", "estimator=[mekf]"])
    data = build_data(data_settings(cfg))
    est = build_estimator("mekf", cfg.estimator.mekf, data.model)
    crashes = (np.array([-1, 5, -1]), {1: "test crash"})
    result = run_estimator("mekf", est, data, 1e6, 0, crashes=crashes, smoother=SmootherSettings("fixed_interval"))
    assert result.diverged.tolist() == [False, True, False]
    assert result.smoothed.diverged.tolist() == [False, True, False]
    assert "test crash" in result.smoothed.reasons[1]
    assert np.isnan(result.smoothed.rmse[1]).all() and np.isfinite(result.smoothed.rmse[[0, 2]]).all()


@pytest.mark.parametrize("reset", [True, False])
def test_the_mekf_smoother_resets_its_covariance_as_the_filter_does(reset):
    """The smoothed correction δ is injected with ⊞ and, when the filter resets its covariance,
    the smoothed covariance is reset the same way, ``J P Jᵀ`` with ``J`` the model's reset Jacobian
    at δ (second order in δ, so the RMSE tests above cannot see it: checked here directly)."""
    data = build_data(compose_settings(["model=attitude", "runs=2", "duration=0.1", "progress=false"]))
    model = data.model
    form = ErrorStateEKF(model, reset_jacobian=reset).smoothing_form()
    rng = np.random.default_rng(3)
    n = model.n_err
    x = data.truth[:, 3]
    G = 0.5 * np.eye(n) + 0.05 * rng.standard_normal((2, n, n))
    predicted = model.boxplus(x, 0.02 * rng.standard_normal((2, n)))
    later = model.boxplus(predicted, 0.2 * rng.standard_normal((2, n)))
    P = np.broadcast_to(np.eye(n), (2, n, n)) * 0.3
    mean, spread = form.correct(x, SmootherStep(G, predicted, P), later, P)
    delta = (G @ model.boxminus(later, predicted)[..., None])[..., 0]
    np.testing.assert_allclose(mean, model.boxplus(x, delta), rtol=0, atol=1e-15)
    J = model.reset_jacobian(x, delta) if reset else np.eye(n)
    np.testing.assert_allclose(spread, J @ P @ np.swapaxes(J, -1, -2), rtol=1e-14, atol=1e-15)
    assert reset == (not np.allclose(spread, P))


def test_a_composed_config_pickles_into_a_fresh_process(tmp_path):
    """The estimator schemas carry the smoother keys in classes made at run time; a config holding
    them must still reach worker processes and launchers (pickled, unpickled where they were never
    built)."""
    cfg = compose_config(["estimator=[srukf,pf,mekf]", "estimator.srukf.smoother=fixed_lag"])
    path = tmp_path / "cfg.pkl"
    path.write_bytes(pickle.dumps(cfg))
    code = f"import pickle; c = pickle.load(open({str(path)!r}, 'rb')); print(c.estimator.srukf.smoother)"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "fixed_lag"


@pytest.mark.slow
def test_the_command_prints_smoothed_rows_beside_the_filtered_ones(tmp_path):
    """``quadest estimator.srukf.smoother=fixed_interval``: the smoothed row is in the printed
    summary, the RMSE table, the paired comparison and summary.json, scored on the same runs."""
    out = tmp_path / "job"
    command = [
        sys.executable, "-c", "from quadest.app.cli import main; main()",
        "estimator=[ekf,srukf]", "estimator.srukf.smoother=fixed_interval", "runs=2", "duration=0.5",
        "cache.enabled=false", f"hydra.run.dir={out}",
    ]  # fmt: skip
    done = subprocess.run(command, capture_output=True, text=True, check=False, cwd=tmp_path)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "srukf+smoothed: 0 of 2 runs diverged" in done.stdout
    assert "srukf+smoothed - srukf" in done.stdout
    summary = (out / "rmse_summary.csv").read_text()
    assert "srukf+smoothed" in summary and "ekf+smoothed" not in summary
    assert "srukf+smoothed" in (out / "summary.json").read_text()


def test_the_particle_smoothers_draws_are_per_run_and_apart_from_the_filters():
    """Each run's backward draws come from its own child of its estimator seed: two runs never
    share them, and they are not the filter's own stream."""
    seeds = build_data(compose_settings(["model=ungm", "runs=3", "duration=2"])).estimator_seeds
    first = [np.random.default_rng(smoother_seed(s)).random(4) for s in seeds]
    assert not any(np.array_equal(a, b) for i, a in enumerate(first) for b in first[i + 1 :])
    for seed, draws in zip(seeds, first, strict=True):
        assert not np.array_equal(np.random.default_rng(seed).random(4), draws)
        np.testing.assert_array_equal(np.random.default_rng(smoother_seed(seed)).random(4), draws)


def test_a_table_with_smoothed_rows_says_its_pcrlb_is_the_filtering_bound():
    """A smoother uses later measurements, so the filtering PCRLB is not its floor: the caption of a
    job with a smoother says so, one without does not (every job kind: tests/test_captions.py)."""
    from quadest.evaluation.pcrlb import pcrlb_caption

    assert "filtering bound" in pcrlb_caption("ungm", smoothed=True) and "floor" in pcrlb_caption("ungm", True)
    assert "filtering bound" not in pcrlb_caption("ungm")
