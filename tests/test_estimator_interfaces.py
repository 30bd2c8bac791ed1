"""The interfaces the filter families beyond the EKF and UKF build on:

1. estimator randomness (per-run generators from the experiment's SeedSequence, its own stream);
2. noise as distributions (sampling and log-density on the model);
3. several sensors (named measurement models, availability, NIS per sensor);
4. states that are not vectors (boxplus/boxminus in the mean, the errors and the NEES);
5. parameters that describe themselves (ranges in Params, parameter columns in the tables).
"""

from __future__ import annotations

import itertools
from typing import ClassVar

import numpy as np
import pytest
from scipy.stats import multivariate_normal

from helpers import compose_config, compose_settings, random_spd
from quadest.app.settings import data_settings
from quadest.app.validate import validate
from quadest.errors import ConfigError
from quadest.estimators.base import Estimator, PerRunAdapter
from quadest.estimators.central_difference import SRCDKF
from quadest.estimators.cubature import CKF
from quadest.estimators.filterpy_ekf import BatchedFilterpyEKF
from quadest.estimators.filterpy_ukf import FilterpyUKF
from quadest.estimators.srukf import SRUKF
from quadest.evaluation.metrics import tidy_metrics
from quadest.evaluation.pcrlb import pcrlb_variances
from quadest.models.base import MeasurementModel
from quadest.models.functional import FunctionalModel, LinearGaussianModel
from quadest.montecarlo.data import MonteCarloData
from quadest.runner import run_estimator
from quadest.sensors.record import SensorRecord
from quadest.simulation.registry import build_data

LINEAR = ["model=linear", "sample_period=0.1", "duration=1.0", "progress=false"]


# --- 1. estimator randomness -------------------------------------------------------------------


class _Draws(Estimator):
    """Records one draw per run per step from the generators the runner hands it."""

    capabilities: ClassVar[frozenset[str]] = frozenset({"random"})

    def initialize(self, x0, P0):
        self.x, self.P = x0.copy(), P0.copy()
        self._reset_failures(len(x0))
        self.draws = []

    def predict(self, u):
        self.draws.append([rng.standard_normal() for rng in self.rngs])

    def update(self, z, u, sensor=None):
        pass

    @property
    def mean(self):
        return self.x

    @property
    def covariance(self):
        return self.P


def _draws(runs: int, seed: int = 3) -> np.ndarray:
    data = build_data(compose_settings([*LINEAR, f"runs={runs}", f"seed={seed}"]))
    est = _Draws(data.model)
    run_estimator("draws", est, data, 1e9)
    return np.array(est.draws)


def test_random_estimator_gets_reproducible_per_run_generators_of_its_own_stream():
    a, b = _draws(3), _draws(3)
    assert np.array_equal(a, b)  # same seed, same numbers
    assert np.array_equal(_draws(5)[:, :3], a)  # run i is the same whatever the number of runs
    assert not np.array_equal(_draws(3, seed=4), a)
    assert len({tuple(col) for col in a.T}) == 3  # each run its own stream


def test_adding_a_random_estimator_changes_no_other_estimators_numbers():
    data = build_data(compose_settings([*LINEAR, "runs=3"]))
    alone = run_estimator("srukf", SRUKF(data.model), data, 1e9)
    run_estimator("draws", _Draws(data.model), data, 1e9)
    again = run_estimator("srukf", SRUKF(data.model), data, 1e9)
    assert np.array_equal(alone.sq_error_sum, again.sq_error_sum)


def test_generators_come_from_the_datas_estimator_seeds():
    data = build_data(compose_settings([*LINEAR, "runs=2", "seed=3"]))
    first = [np.random.default_rng(s).standard_normal() for s in data.estimator_seeds]
    assert np.array_equal(_draws(2)[0], first)


def test_per_run_adapter_hands_each_run_its_generator():
    data = build_data(compose_settings([*LINEAR, "runs=2"]))
    seen = []

    class Single(FilterpyUKF):
        capabilities: ClassVar[frozenset[str]] = frozenset({"innovation", "random"})

        def set_generator(self, rng):
            seen.append(rng.standard_normal())

    adapter = PerRunAdapter(data.model, Single)
    assert "random" in adapter.capabilities
    run_estimator("single", adapter, data, 1e9)
    assert seen == [np.random.default_rng(s).standard_normal() for s in data.estimator_seeds]


def test_per_run_adapter_flags_a_run_whose_mean_stops_being_finite_without_raising():
    """A run filter that returns a NaN mean or an infinite covariance (no exception) is flagged with
    the adapter's reason and keeps its last finite values; the other runs go on; a filter that
    raises is flagged with its error. One check per batch must give the flags a check per run gave."""
    data = build_data(compose_settings([*LINEAR, "runs=4"]))
    run_numbers = itertools.count()

    class Single(FilterpyUKF):
        def __init__(self, model):
            super().__init__(model)
            self.run, self.steps = next(run_numbers), 0

        def predict(self, u):
            super().predict(u)
            self.steps += 1
            if self.run == 1 and self.steps == 2:
                self.kf.x = np.full_like(self.kf.x, np.nan)
            if self.run == 2 and self.steps == 3:
                raise ValueError("plugin bug")
            if self.run == 3 and self.steps == 2:
                self.kf.P = np.full_like(self.kf.P, np.inf)

    adapter = PerRunAdapter(data.model, Single)
    adapter.initialize(data.x0, np.broadcast_to(data.P0, (4, *data.P0.shape[-2:])).copy())
    means = []
    for k in range(1, 6):
        adapter.predict(data.inputs[:, k - 1])
        means.append(adapter.mean.copy())
    assert adapter.failed.tolist() == [False, True, True, True]
    assert adapter.failure_reasons == {
        1: "non-finite mean or covariance",
        2: "ValueError: plugin bug",
        3: "non-finite mean or covariance",
    }
    assert np.isfinite(adapter.mean).all() and np.isfinite(adapter.covariance).all()
    np.testing.assert_array_equal(means[-1][1], means[0][1])  # frozen at its mean after step 1
    np.testing.assert_array_equal(means[-1][2], means[1][2])  # after step 2
    np.testing.assert_array_equal(means[-1][3], means[0][3])  # its covariance failed at step 2
    assert not np.array_equal(means[-1][0], means[1][0])  # run 0 goes on


def test_per_run_adapter_lets_a_configuration_error_fail_the_job():
    """A single-run plugin that refuses its configuration while it runs raises ``ConfigError``
    out of the adapter (the job fails with its one line), rather than flagging every run diverged."""
    data = build_data(compose_settings([*LINEAR, "runs=2"]))

    class Refuses(FilterpyUKF):
        def predict(self, u):
            raise ConfigError("estimator.single.gain", 2.0, "must be < 1")

    adapter = PerRunAdapter(data.model, Refuses)
    adapter.initialize(data.x0, np.broadcast_to(data.P0, (2, *data.P0.shape[-2:])).copy())
    with pytest.raises(ConfigError, match=r"estimator\.single\.gain"):
        adapter.predict(data.inputs[:, 0])


# --- 2. noise as distributions -----------------------------------------------------------------


@pytest.mark.parametrize("backend", ["numba", "numpy"])
@pytest.mark.parametrize("structure", ["correlated", "diagonal"])
def test_gaussian_noise_log_density_and_sampling(structure, backend, monkeypatch):
    """Against scipy (its eigendecomposition route agrees to round-off: rtol 1e-10) and against the
    Cholesky-and-solve rule written out here (a few ulps: rtol 1e-14). A diagonal covariance takes
    the models' shortcut (no solve, one product per drawn value), whose draws must be the general
    rule's values exactly (the matrix product's other terms are exact zeros); a semi-definite
    diagonal still has no density (Cholesky raises, as for any singular covariance). On both
    backends (``QUADEST_KERNELS``): the diagonal shortcut is a compiled kernel on numba and its
    numpy reference otherwise."""
    monkeypatch.setenv("QUADEST_KERNELS", backend)
    rng = np.random.default_rng(0)
    Q, R = random_spd(rng, 3, 0.5), random_spd(rng, 2, 0.2)
    if structure == "diagonal":
        Q, R = np.diag([0.3, 2.0, 1e-5]), np.diag([0.1, 7.0])
        with pytest.raises(np.linalg.LinAlgError):
            LinearGaussianModel(np.eye(2), np.eye(2), np.diag([1.0, 0.0]), R).process_noise_logpdf(np.ones((1, 2)))
    draws = LinearGaussianModel(np.eye(3), np.eye(2, 3), Q, R).sample_process_noise(np.random.default_rng(2), (9,))
    assert np.array_equal(draws, np.random.default_rng(2).standard_normal((9, 3)) @ np.linalg.cholesky(Q).T)
    model = LinearGaussianModel(np.eye(3), np.eye(2, 3), Q, R)
    w = rng.standard_normal((4, 5, 3))
    L = np.linalg.cholesky(Q)
    white = np.linalg.solve(L, w.reshape(-1, 3).T).T.reshape(w.shape)
    written_out = -0.5 * np.sum(white**2, axis=-1) - 1.5 * np.log(2 * np.pi) - np.sum(np.log(np.diag(L)))
    np.testing.assert_allclose(model.process_noise_logpdf(w), written_out, rtol=1e-14)
    np.testing.assert_allclose(model.process_noise_logpdf(w), multivariate_normal(np.zeros(3), Q).logpdf(w), rtol=1e-10)
    v = rng.standard_normal((7, 2))
    np.testing.assert_allclose(
        model.measurement_noise_logpdf(v), multivariate_normal(np.zeros(2), R).logpdf(v), rtol=1e-10
    )
    N = 40_000
    draws = model.sample_process_noise(np.random.default_rng(1), (N,))
    # Each sample-covariance entry has standard deviation √((Q_ii Q_jj + Q_ij²)/N): allow 5 of them.
    sd = np.sqrt((np.outer(np.diag(Q), np.diag(Q)) + Q**2) / N)
    assert (np.abs(np.cov(draws.T) - Q) <= 5 * sd).all()
    assert (np.abs(draws.mean(0)) <= 5 * np.sqrt(np.diag(Q) / N)).all()


# --- 3. several sensors ------------------------------------------------------------------------


def _two_sensor_problem(runs: int = 2, steps: int = 30):
    """2-D constant velocity, positions every step (primary), velocities every third step."""
    rng = np.random.default_rng(5)
    T = 0.1
    A = np.eye(4)
    A[0, 2] = A[1, 3] = T
    C = np.eye(2, 4)
    Cv = np.eye(4)[2:]
    Q, R, Rv, P0 = random_spd(rng, 4, 0.01), random_spd(rng, 2, 0.2), random_spd(rng, 2, 0.05), random_spd(rng, 4, 1)
    model = LinearGaussianModel(A, C, Q, R, dt=T, batch_size=runs)
    model.sensors = {"velocity": MeasurementModel(lambda x, u: x @ Cv.T, Rv, ("vx", "vy"))}
    x = np.zeros((runs, steps + 1, 4))
    x[:, 0] = rng.standard_normal((runs, 4))
    for k in range(1, steps + 1):
        x[:, k] = x[:, k - 1] @ A.T + rng.standard_normal((runs, 4)) @ np.linalg.cholesky(Q).T
    z = x @ C.T + rng.standard_normal((runs, steps + 1, 2)) @ np.linalg.cholesky(R).T
    zv = x @ Cv.T + rng.standard_normal((runs, steps + 1, 2)) @ np.linalg.cholesky(Rv).T
    available = np.arange(steps + 1) % 3 == 0
    x0 = x[:, 0] + rng.standard_normal((runs, 4)) @ np.linalg.cholesky(P0).T
    data = MonteCarloData(
        model, np.arange(steps + 1) * T, x, np.zeros((runs, steps + 1, 0)), np.zeros((runs, steps + 1, 0)), z, x0, P0,
        np.zeros((runs, 0)), [np.random.SeedSequence(i) for i in range(runs)],
        sensors={"velocity": SensorRecord(zv, available)},
    )  # fmt: skip
    return data, (A, C, Cv, Q, R, Rv)


def _sequential_kalman(data, mats):
    """The Kalman filter with sequential updates, written out: predict, position, then velocity."""
    A, C, Cv, Q, R, Rv = mats
    B, K1 = data.truth.shape[:2]
    means, stds = np.zeros((B, K1, 4)), np.zeros((B, K1, 4))
    for i in range(B):
        x, P = data.x0[i].copy(), data.P0.copy()
        means[i, 0], stds[i, 0] = x, np.sqrt(np.diag(P))
        for k in range(1, K1):
            x, P = A @ x, A @ P @ A.T + Q
            updates = [(C, R, data.measurements[i, k])]
            if data.sensors["velocity"].available[k]:
                updates.append((Cv, Rv, data.sensors["velocity"].values[i, k]))
            for H, Rm, z in updates:
                S = H @ P @ H.T + Rm
                K = P @ H.T @ np.linalg.inv(S)
                x, P = x + K @ (z - H @ x), P - K @ S @ K.T
            means[i, k], stds[i, k] = x, np.sqrt(np.diag(P))
    return means, stds


@pytest.mark.parametrize(
    "make",
    [
        lambda m: SRUKF(m),
        lambda m: CKF(m),
        lambda m: SRCDKF(m),
        lambda m: BatchedFilterpyEKF(m),
        lambda m: PerRunAdapter(m, FilterpyUKF),
        lambda m: PerRunAdapter(m, FilterpyUKF, vectorize_points=False),
    ],
    ids=["srukf", "ckf", "srcdkf", "filterpy-ekf", "filterpy-ukf", "filterpy-ukf-per-point"],
)
def test_several_sensors_at_their_own_rates_equal_sequential_kalman_updates(make):
    data, mats = _two_sensor_problem()
    res = run_estimator("f", make(data.model), data, 1e9, saved_runs=2)
    means, stds = _sequential_kalman(data, mats)
    assert np.abs(res.saved["estimate"] - means).max() <= 1e-9 * np.abs(means).max()
    assert np.abs(res.saved["std"] - stds).max() <= 1e-9 * stds.max()
    _, count = res.sensor_nis["velocity"]
    assert (count == data.sensors["velocity"].available[1:].sum()).all()
    assert np.isfinite(res.mean_sensor_nis("velocity")).all()


def test_sensor_nis_is_the_normalised_innovation_of_that_sensor():
    """Average NIS of the velocity sensor over many runs is near its dimension (2) for a
    consistent linear filter: mean of a χ²(2) over N samples has sd 2/√N."""
    data, _ = _two_sensor_problem(runs=200, steps=30)
    res = run_estimator("f", SRUKF(data.model), data, 1e9)
    total, count = res.sensor_nis["velocity"]
    mean = total.sum() / count.sum()
    assert abs(mean - 2.0) <= 4 * 2.0 / np.sqrt(count.sum())


# --- 4. states that are not vectors ------------------------------------------------------------


def _wrap(a):
    return (a + np.pi) % (2 * np.pi) - np.pi


class _Circle(FunctionalModel):
    """An angle on the circle: boxplus and boxminus wrap to (−π, π]."""

    def boxplus(self, x, dx):
        return _wrap(x + dx)

    def boxminus(self, y, x):
        return _wrap(y - x)


def test_angle_filter_with_boxplus_equals_the_unwrapped_filter():
    """A rotating angle measured by (cos, sin), filtered near ±π with wrapping hooks, equals the
    same filter on the angle shifted by π (where it never wraps), to round-off. Without the hooks
    the mean of points straddling ±π would be near 0, off by π."""
    steps, B, T, omega = 20, 2, 0.1, 0.05
    Q, R = np.array([[1e-4]]), 0.01 * np.eye(2)

    def f(x, u):
        return x + omega * T

    wrapped = _Circle(f, lambda x, u: np.concatenate([np.cos(x), np.sin(x)], -1), Q, R, batch_size=B)
    shifted = FunctionalModel(f, lambda x, u: -np.concatenate([np.cos(x), np.sin(x)], -1), Q, R, batch_size=B)
    rng = np.random.default_rng(2)
    truth = np.pi - 0.03 + omega * T * np.arange(steps + 1)[None, :, None] + np.zeros((B, 1, 1))
    z = np.concatenate([np.cos(truth), np.sin(truth)], -1) + 0.1 * rng.standard_normal((B, steps + 1, 2))
    P0 = np.array([[0.01]])
    x0 = truth[:, 0] + 0.05  # just past +π: the wrapped filter starts on the other side

    def data(model, x_true, start):
        return MonteCarloData(
            model, np.arange(steps + 1) * T, x_true, np.zeros((B, steps + 1, 0)), np.zeros((B, steps + 1, 0)), z,
            start, P0, np.zeros((B, 0)), [np.random.SeedSequence(i) for i in range(B)],
        )  # fmt: skip

    a = run_estimator("a", SRUKF(wrapped), data(wrapped, _wrap(truth), _wrap(x0)), 1e9, saved_runs=B)
    b = run_estimator("b", SRUKF(shifted), data(shifted, truth - np.pi, x0 - np.pi), 1e9, saved_runs=B)
    assert (np.abs(_wrap(a.saved["estimate"] - (b.saved["estimate"] + np.pi))) <= 1e-10).all()
    assert np.allclose(a.saved["std"], b.saved["std"], rtol=1e-9)
    assert np.allclose(a.rmse, b.rmse, rtol=1e-8) and np.allclose(a.mean_nees, b.mean_nees, rtol=1e-8)
    assert (a.saved["estimate"][:, -1] < 0).all()  # it did cross +π


# --- 5. parameters that describe themselves ----------------------------------------------------


@pytest.mark.parametrize(
    ("overrides", "key", "allowed"),
    [
        (["estimator=[cdkf]", "estimator.cdkf.h=0.5"], "estimator.cdkf.h", ">= 1"),
        (["estimator=[ghkf]", "estimator.ghkf.p=0"], "estimator.ghkf.p", "integer"),
        (["estimator=[srukf]", "estimator.srukf.kappa=-7"], "estimator.srukf.kappa", "kappa > -6"),
        (["estimator=[ukf]", "estimator.ukf.alpha=0"], "estimator.ukf.alpha", "> 0"),
    ],
)
def test_parameter_ranges_come_from_the_params_dataclass(overrides, key, allowed):
    with pytest.raises(ConfigError) as err:
        validate(compose_config(overrides))
    assert err.value.key == key and allowed in str(err.value)


def test_metrics_take_parameter_columns_from_every_estimators_params():
    cfg = compose_config([*LINEAR, "runs=2", "estimator=[cdkf,ghkf,srukf]", "estimator.cdkf.h=2.0"])
    data = build_data(data_settings(cfg))
    results = [run_estimator(name, cls(data.model), data, 1e9) for name, cls in (("cdkf", SRCDKF), ("srukf", SRUKF))]
    params = {"cdkf": {"kind": "cdkf", "h": 2.0, "augmented": False}, "srukf": {"kind": "srukf", "alpha": 0.5}}
    table = tidy_metrics(results, data, params, {"seed": 1})
    assert set(table[table.estimator == "cdkf"]["h"]) == {2.0}
    assert table[table.estimator == "srukf"]["h"].isna().all()
    assert set(table[table.estimator == "srukf"]["alpha"]) == {0.5}


def test_filterpy_ukf_innovation_is_a_factor_like_every_estimators():
    data = build_data(compose_settings([*LINEAR, "runs=2"]))
    adapter = PerRunAdapter(data.model, FilterpyUKF)
    res = run_estimator("ukf", adapter, data, 1e9)
    ours = run_estimator("srukf", SRUKF(data.model), data, 1e9)
    assert np.allclose(res.mean_nis, ours.mean_nis, rtol=1e-8)
    _, L = adapter.innovation()
    S = adapter.filters[0].kf.S
    assert np.allclose(L[0] @ L[0].T, S, rtol=1e-12) and np.allclose(L[0], np.tril(L[0]))


class _Collapsed(_Draws):
    """Keeps its start as the estimate with a zero covariance (a cloud collapsed onto one
    particle) and reports a per-run diagnostic."""

    capabilities: ClassVar[frozenset[str]] = frozenset()

    def initialize(self, x0, P0):
        super().initialize(x0, np.zeros_like(P0))

    def predict(self, u):
        pass

    def diagnostics(self):
        return {"ess_mean": np.arange(len(self.x), dtype=float)}


def test_singular_cloud_covariance_makes_nees_unavailable_not_a_divergence():
    data = build_data(compose_settings([*LINEAR, "runs=3"]))
    gaussian = run_estimator("g", _Collapsed(data.model), data, 1e9)
    assert gaussian.diverged.all()  # a Gaussian filter's singular covariance is a failure

    class Cloud(_Collapsed):
        capabilities: ClassVar[frozenset[str]] = frozenset({"cloud"})

    cloud = run_estimator("c", Cloud(data.model), data, 1e9)
    assert not cloud.diverged.any() and (cloud.steps == data.truth.shape[1] - 1).all()
    assert (cloud.nees_steps == 0).all() and np.isnan(cloud.mean_nees).all()
    assert np.isfinite(cloud.rmse).all()
    table = tidy_metrics([cloud], data, {"c": {"kind": "c", "proposal": [1.0, 2.0]}}, {"seed": 1})
    assert list(table.groupby("run")["ess_mean"].first()) == [0.0, 1.0, 2.0]
    assert set(table["proposal"]) == {"[1.0, 2.0]"}  # list-valued parameters tabulate as text


@pytest.mark.integration
def test_job_summary_reports_nis_per_sensor(tmp_path, monkeypatch):
    """summary.json carries the mean NIS of every further sensor (here: velocity every 3rd step)."""
    import json

    import quadest.app.job as job
    import quadest.app.open_loop_job as open_loop_job

    data, _ = _two_sensor_problem(runs=3)
    data.labels = {"model": "linear"}
    monkeypatch.setattr(open_loop_job, "build_data", lambda cfg: data)
    cfg = compose_config([*LINEAR, "runs=3", "estimator=[srukf]", "workers=1", "output.saved_runs=0"])
    job.run_job(cfg, tmp_path)
    summary = json.loads((tmp_path / "summary.json").read_text())
    res = run_estimator("srukf", SRUKF(data.model), data, 1e9)
    expected = float(np.nanmean(res.mean_sensor_nis("velocity")))
    assert summary["estimators"]["srukf"]["nis_by_sensor"]["velocity"] == pytest.approx(expected, rel=1e-12)


def test_pcrlb_counts_the_further_sensors_at_their_samples():
    """On a linear-Gaussian model whose truth follows the model, the PCRLB recursion is the Kalman
    filter's covariance (Tichavský et al. 1998, §IV), here with the velocity sensor's sequential
    updates every third step. The information form loses about cond(Q)·eps; 1e-9 relative is
    far above that and far below the velocity sensor's effect."""
    data, mats = _two_sensor_problem(runs=2, steps=30)
    _, stds = _sequential_kalman(data, mats)
    assert np.allclose(pcrlb_variances(data), stds[0] ** 2, rtol=1e-9, atol=0)
