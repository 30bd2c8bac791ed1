"""Attitude metrics of the job: the derived errors (error angle, roll, pitch, yaw in
degrees) against scipy, their accumulation in the runner, the bias convergence time, and what the
``quadest`` command writes and prints for ``model=attitude``."""

from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest
from scipy.spatial.transform import Rotation

from helpers import compose_config
from quadest.app.settings import data_settings
from quadest.estimators.registry import build_estimator
from quadest.evaluation.metrics import convergence_table, convergence_time
from quadest.models.attitude import attitude_errors_deg
from quadest.numerics import quaternion as quat
from quadest.runner import run_estimator
from quadest.simulation.registry import build_data
from test_cli import quadest

ROUND_OFF_DEG = 1e-9
"""Round-off of both computations: ~1e-16 rad per operation, amplified by the arcsin of the pitch
at most 1/cos 85° ≈ 11 away from gimbal lock (|pitch| ≤ 85°), × 57.3 deg/rad: ~1e-13 deg; 1e-9
leaves room for the different algorithms, and any real error (a sign, a wrap) is ≫ 1e-3 deg."""


def _scalar_last(q: np.ndarray) -> np.ndarray:
    return q[..., [1, 2, 3, 0]]


def _random_attitudes(rng: np.random.Generator, count: int) -> np.ndarray:
    """Unit quaternions, scalar first, with pitch within ±85° (roll and yaw are defined)."""
    q = Rotation.random(4 * count, random_state=rng).as_quat()[:, [3, 0, 1, 2]]
    pitch = np.degrees(Rotation.from_quat(_scalar_last(q)).as_euler("ZYX")[:, 1])
    return q[np.abs(pitch) <= 85.0][:count]


@pytest.mark.parametrize("spread", ["independent", "small"])
def test_attitude_errors_match_scipy_rotation(spread):
    """Error angle = magnitude of R_true⁻¹ R_est; roll, pitch, yaw errors = differences of scipy's
    intrinsic ZYX angles ("ZYX": yaw, pitch, roll of R = Rz Ry Rx), wrapped by (d + 180) mod 360
    − 180. Independent attitudes give errors up to 180°; small ones (≤ 0.6°) test the small-angle
    branch. The sign of the estimate's quaternion must not matter."""
    rng = np.random.default_rng(20261122)
    truth = _random_attitudes(rng, 200)
    if spread == "independent":
        est = _random_attitudes(rng, 200)
    else:
        est = quat.multiply(truth, quat.exp(rng.uniform(-6e-3, 6e-3, (200, 3))))
    est = np.where(rng.random((200, 1)) < 0.5, -est, est)
    r_true, r_est = Rotation.from_quat(_scalar_last(truth)), Rotation.from_quat(_scalar_last(est))
    angle = np.degrees((r_true.inv() * r_est).magnitude())
    d = np.degrees(r_est.as_euler("ZYX") - r_true.as_euler("ZYX"))[:, ::-1]  # roll, pitch, yaw
    expected = np.column_stack([angle, (d + 180.0) % 360.0 - 180.0])

    got = attitude_errors_deg(np.concatenate([est, np.zeros((200, 6))], axis=1), truth)
    assert got.shape == (200, 4)
    np.testing.assert_allclose(got, expected, rtol=0, atol=ROUND_OFF_DEG)


def test_roll_pitch_yaw_errors_wrap_to_plus_minus_180():
    """Hand-computed: an estimate of 179° against a truth of −179° is −2°, not 358°; −179°
    against 179° is +2°; a difference of exactly ±180° is +180 (the interval is (−180, 180]).
    The error angle of each is 2° (180° for the last), whatever the Euler angles."""
    cases = np.radians(
        [  # (truth roll, pitch, yaw), (estimate roll, pitch, yaw) in degrees
            [[0.0, 0.0, -179.0], [0.0, 0.0, 179.0]],
            [[0.0, 0.0, 179.0], [0.0, 0.0, -179.0]],
            [[-179.0, 10.0, 0.0], [179.0, 10.0, 0.0]],
            [[0.0, 0.0, 90.0], [0.0, 0.0, -90.0]],
        ]
    )
    expected = np.array([[0.0, 0.0, -2.0], [0.0, 0.0, 2.0], [-2.0, 0.0, 0.0], [0.0, 0.0, 180.0]])
    got = attitude_errors_deg(quat.from_euler(cases[:, 1]), quat.from_euler(cases[:, 0]))
    np.testing.assert_allclose(got[:, 1:], expected, atol=1e-9)
    np.testing.assert_allclose(got[:, 0], [2.0, 2.0, 2.0, 180.0], atol=1e-9)


def test_runner_derived_rmse_equals_the_saved_series():
    """model=attitude, 3 runs × 1 s, every run saved; run 1 is ended at step 41 (a crash, as the
    closed loop flags it). The runner's sums of squared derived errors equal those of the saved
    estimates against the truth over steps 1..K (a diverged run's saved estimate is NaN from its
    divergence on, so its sum stops there), and the per-run RMSE is their time mean's root for the
    runs that did not diverge, NaN for the one that did. Tolerance: round-off of 100-term sums."""
    cfg = compose_config(["model=attitude", "runs=3", "duration=1", "scenario=figure8"])
    data = build_data(data_settings(cfg))
    est = build_estimator("mekf", {"kind": "mekf"}, data.model)
    crashes = (np.array([-1, 40, -1]), {1: "test"})
    res = run_estimator("mekf", est, data, divergence_bound=50.0, saved_runs=3, crashes=crashes)
    assert list(res.diverged) == [False, True, False] and res.diverged_step[1] == 41

    err = data.model.derived_errors(res.saved["estimate"][:, 1:], data.truth[:, 1:])
    assert err.shape == (3, data.time.size - 1, 4)
    np.testing.assert_allclose(res.derived_sq_error_sum, np.nansum(err**2, axis=1), rtol=1e-12)
    direct = np.sqrt(np.mean(err**2, axis=1))
    np.testing.assert_allclose(res.derived_rmse[[0, 2]], direct[[0, 2]], rtol=1e-12)
    assert np.isnan(res.derived_rmse[1]).all()


def test_convergence_time_on_constructed_curves():
    """RMS = e^(−t) on t = 0, 0.01, …, 3 against the threshold 0.5: below from t = 0.70 (the first
    grid point above ln 2 = 0.693). A bump above the threshold at t = 1.5 moves it to 1.51; a curve
    that ends above (or with no run alive, NaN) has not converged; one always below converged at
    its first time."""
    t = np.round(np.arange(301) * 0.01, 10)
    rms = np.exp(-t)
    assert convergence_time(t, rms, 0.5) == pytest.approx(0.70)
    bumped = rms.copy()
    bumped[150] = 0.6
    assert convergence_time(t, bumped, 0.5) == pytest.approx(1.51)
    assert np.isnan(convergence_time(t, rms + 0.5, 0.5))
    assert np.isnan(convergence_time(t, np.append(rms[:-1], np.nan), 0.5))
    assert convergence_time(t, 0.1 * rms, 0.5) == 0.0


def test_convergence_table_reads_the_ensemble_curve_of_each_bias_state():
    """A bias state with prior σ = 2 (P0 = 4) whose RMS over the live runs (sq_error_t/alive_t)
    is 2 e^(−t): the threshold 1 (half the prior σ) is crossed at t = ln 2 → 0.70 on the grid;
    the final RMS is the root of the pooled mean over the last 10 % of the steps (the last 30 of
    steps 1..300)."""
    time = np.round(np.arange(301) * 0.01, 10)
    alive = np.full(301, 5.0)
    alive[0] = 0.0
    rms = 2.0 * np.exp(-time)
    sq = np.zeros((301, 2))
    sq[:, 1] = alive * rms**2
    model = SimpleNamespace(bias_states=("bg_x",), error_names=("dtheta_x", "bg_x"), error_units=("rad", "rad/s"))
    data = SimpleNamespace(model=model, time=time, P0=np.diag([1.0, 4.0]))
    result = SimpleNamespace(name="f", sq_error_t=sq, alive_t=alive)
    row = convergence_table([result], data).iloc[0]
    assert (row["state"], row["unit"], row["prior_std"], row["threshold"]) == ("bg_x", "rad/s", 2.0, 1.0)
    assert row["convergence_time_s"] == pytest.approx(0.70)
    assert row["final_rms"] == pytest.approx(np.sqrt(np.mean(rms[-30:] ** 2)), rel=1e-12)


@pytest.mark.integration
@pytest.mark.slow
def test_attitude_job_reports_degrees_convergence_figures_and_nine_dof(tmp_path):
    """A tiny model=attitude job: the printed NEES has 9 dof (the error state), not 10 (the
    quaternion state); metrics.csv and the paired comparison carry the derived rows in degrees;
    convergence.csv has one row per estimator and bias state; the attitude figures are drawn."""
    out = tmp_path / "run"
    proc = quadest(
        ["model=attitude", "estimator=[mekf,srukf]", "runs=2", "duration=0.3", "progress=false",
         "cache.enabled=false", f"hydra.run.dir={out}"],
        tmp_path,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert "(9 dof" in proc.stdout and "(10 dof" not in proc.stdout
    assert "roll [deg]" in proc.stdout
    table = pd.read_csv(out / "metrics.csv")
    derived = table[table["quantity"] == "derived"]
    assert len(derived) == 2 * 2 * 4  # estimators × runs × (angle, roll, pitch, yaw)
    assert set(derived["state"]) == {"error_angle", "roll", "pitch", "yaw"} and set(derived["unit"]) == {"deg"}
    paired = pd.read_csv(out / "paired_comparison.csv")
    assert set(paired.loc[paired["quantity"] == "derived", "state"]) == {"error_angle", "roll", "pitch", "yaw"}
    convergence = pd.read_csv(out / "convergence.csv")
    assert len(convergence) == 2 * 6
    assert json.loads((out / "summary.json").read_text())["error_names"][0] == "dtheta_x"
    for name in ("attitude_errors.png", "bias_estimates.png"):
        assert (out / "figures" / name).is_file(), name


def test_the_settled_attitude_table_leaves_out_the_transient_and_diverged_runs(tmp_path):
    """``python -m quadest.evaluation.attitude_figures DIR --settle S`` (the second command of
    results/attitude): on level attitudes with a yaw offset of 30° before ``S`` and a known one after,
    the RMS error angle and yaw error are that offset, roll and pitch 0; a run that diverged (NaN)
    is left out."""
    from quadest.evaluation.attitude_figures import main

    time = np.arange(0.0, 2.0, 0.1)
    yaw = np.random.default_rng(3).uniform(-3.0, 3.0, (3, time.size))
    level = np.stack([np.zeros_like(yaw), np.zeros_like(yaw), yaw], axis=-1)
    truth = np.concatenate([quat.from_euler(level), np.zeros((3, time.size, 6))], axis=-1)
    series = {"time": time, "truth": truth}
    for name, offsets in (("a", [2.0, 2.0, 2.0]), ("b", [1.0, 3.0, np.nan])):
        offset = np.where(time < 1.0, 30.0, np.asarray(offsets)[:, None])
        shifted = level + np.stack([0 * offset, 0 * offset, np.radians(offset)], axis=-1)
        series[f"{name}/estimate"] = np.concatenate([quat.from_euler(shifted), truth[..., 4:]], axis=-1)
    np.savez(tmp_path / "timeseries.npz", **series)
    main([str(tmp_path), "--settle", "1.0"])
    table = pd.read_csv(tmp_path / "attitude_errors.csv").set_index("estimator")
    expected = {"a": 2.0, "b": np.sqrt((1.0 + 9.0) / 2.0)}  # b's third run diverged
    for name, rms in expected.items():
        np.testing.assert_allclose(table.loc[name, ["error_angle_deg", "yaw_deg"]], rms, rtol=1e-9)
        np.testing.assert_allclose(table.loc[name, ["roll_deg", "pitch_deg"]], 0.0, atol=1e-9)


@pytest.mark.integration
@pytest.mark.slow
def test_a_model_without_a_primary_measurement_prints_nis_per_sensor(tmp_path):
    """model=ins updates only through its sensors: the printed line gives each sensor's NIS and
    no meaningless "0 dof" NIS of the empty primary measurement."""
    out = tmp_path / "run"
    proc = quadest(
        ["model=ins", "scenario=figure8", "estimator=[ekf]", "runs=2", "duration=0.5", "progress=false",
         "cache.enabled=false", f"hydra.run.dir={out}"],
        tmp_path,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert "(15 dof" in proc.stdout and "(0 dof" not in proc.stdout
    assert "NIS per sensor gps" in proc.stdout and "vision" in proc.stdout
