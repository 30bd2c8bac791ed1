"""NIS per measurement group (quadest.metrics.groups, docs/metrics.md): the quadratic form of the
group's marginal block of S written out with explicit inverses, a sensor counted only at its own
samples, a Kalman filter's groups against χ²(m_g) over Monte Carlo runs, an over-confident R that
shows in its own group's band only, and an estimator without innovations giving NaN."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from helpers import random_spd
from quadest.estimators.particle import BootstrapPF
from quadest.estimators.srukf import SRUKF
from quadest.metrics.base import BatchStart, StepView
from quadest.metrics.builtin import NIS
from quadest.metrics.consistency import chi2_band
from quadest.metrics.groups import GroupNIS, measurement_groups
from quadest.models.base import MeasurementModel
from quadest.models.functional import LinearGaussianModel
from quadest.montecarlo.data import MonteCarloData
from quadest.runner import run_estimator
from quadest.sensors.record import SensorRecord


class _Grouped(LinearGaussianModel):
    """A linear-Gaussian model whose primary measurement declares ``groups``."""

    def __init__(self, *args, groups, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.groups = groups

    @property
    def measurement_groups(self) -> dict[str, tuple[str, ...]]:
        return self.groups


def _view(k, B, innovations):
    return StepView(k, np.zeros((B, 1)), np.zeros((B, 0)), np.zeros((B, 0)), np.ones((B, 1, 1)),
                    np.full(B, np.nan), np.full(B, np.nan), np.ones(B, dtype=bool), innovations)  # fmt: skip


def _hand_nis(nu, S, index):
    """``ν_gᵀ (S_gg)⁻¹ ν_g`` run by run with an explicit inverse of the group's block."""
    return np.array([v[index] @ np.linalg.inv(s[np.ix_(index, index)]) @ v[index] for v, s in zip(nu, S, strict=True)])


def test_group_nis_is_the_inverse_of_the_marginal_block_at_the_steps_each_measurement_updated():
    """Primary groups {z0, z2} and {z1, z3} of a correlated S (the second group's marginal block is
    not its conditional one), and a sensor that reports at steps 2 and 5 of 6 only, with
    ``ν = L a``: NIS ``|a|²`` = 2 (its dof, inside the band) at step 2 and 20 (outside) at step 5.
    Its average is over those two steps, 11, and its band share over them, one half (over all six
    steps it would have been available on too few to be reported)."""
    rng = np.random.default_rng(3)
    B, K = 5, 6
    model = _Grouped(np.eye(2), np.ones((4, 2)), np.eye(2), random_spd(rng, 4), batch_size=B,
                     groups={"even": ("z0", "z2"), "odd": ("z1", "z3")})  # fmt: skip
    model.sensors = {"speed": MeasurementModel(lambda x, u: x, np.eye(2), ("s0", "s1"))}
    acc = GroupNIS().start(BatchStart(model, np.arange(K + 1) * 0.1, B))
    expected = {"even": np.zeros(B), "odd": np.zeros(B)}
    sensor_steps = {2: np.ones(2), 5: np.array([4.0, 2.0])}
    for k in range(1, K + 1):
        S = np.stack([random_spd(rng, 4) for _ in range(B)])
        nu = rng.normal(size=(B, 4))
        innovations = {None: (nu, np.linalg.cholesky(S))}
        if k in sensor_steps:
            L2 = np.linalg.cholesky(np.stack([random_spd(rng, 2) for _ in range(B)]))
            innovations["speed"] = (L2 @ sensor_steps[k], L2)
        acc.step(_view(k, B, innovations))
        expected["even"] += _hand_nis(nu, S, [0, 2]) / K
        expected["odd"] += _hand_nis(nu, S, [1, 3]) / K
    out = acc.finish()
    np.testing.assert_allclose(out["nis_even"], expected["even"], rtol=1e-10)
    np.testing.assert_allclose(out["nis_odd"], expected["odd"], rtol=1e-10)
    np.testing.assert_allclose(out["nis_speed"], (2.0 + 20.0) / 2, rtol=1e-12)
    assert out["nis_in_band_speed"] == 0.5


def test_measurement_groups_name_a_sensors_groups_after_it_and_refuse_unknown_components():
    model = _Grouped(np.eye(2), np.eye(2), np.eye(2), np.eye(2), groups={"a": ("z0",), "b": ("z1",)})
    model.sensors = {
        "gps": MeasurementModel(lambda x, u: x, np.eye(2), ("p", "v"), groups={"position": ("p",), "velocity": ("v",)}),
        "baro": MeasurementModel(lambda x, u: x[..., :1], np.eye(1), ("h",)),
    }
    assert measurement_groups(model) == {
        "a": (None, [0]), "b": (None, [1]), "gps_position": ("gps", [0]), "gps_velocity": ("gps", [1]),
        "baro": ("baro", [0]),
    }  # fmt: skip
    model.groups = {"a": ("z0", "z9")}
    with pytest.raises(ValueError, match=r"measurement group 'a'.*z9"):
        measurement_groups(model)


def _problem(R_true, R_filter, C, groups, runs, steps, coupled=True, sensor_every=3):
    """A 2-D constant-velocity target: the primary measurement ``C x`` with noise ``R_true`` (the
    filter assumes ``R_filter``) and a velocity sensor (noise known) every ``sensor_every`` steps.
    ``coupled``: correlated Q, sensor noise and P0; otherwise diagonal ones, so that x, vx and
    y, vy are two problems apart."""
    rng = np.random.default_rng(11)
    T = 0.1
    A = np.eye(4)
    A[0, 2] = A[1, 3] = T
    Cv = np.eye(4)[2:]
    if coupled:
        Q, Rv, P0 = random_spd(rng, 4, 0.01), random_spd(rng, 2, 0.05), random_spd(rng, 4, 1.0)
    else:
        Q, Rv, P0 = 0.01 * np.eye(4), 0.05 * np.eye(2), np.eye(4)
    model = _Grouped(A, C, Q, R_filter, dt=T, batch_size=runs, groups=groups)
    model.sensors = {"velocity": MeasurementModel(lambda x, u: x @ Cv.T, Rv, ("vx", "vy"))}
    x = np.zeros((runs, steps + 1, 4))
    x[:, 0] = rng.standard_normal((runs, 4))
    for k in range(1, steps + 1):
        x[:, k] = x[:, k - 1] @ A.T + rng.standard_normal((runs, 4)) @ np.linalg.cholesky(Q).T
    z = x @ C.T + rng.standard_normal((runs, steps + 1, C.shape[0])) @ np.linalg.cholesky(R_true).T
    zv = x @ Cv.T + rng.standard_normal((runs, steps + 1, 2)) @ np.linalg.cholesky(Rv).T
    x0 = x[:, 0] + rng.standard_normal((runs, 4)) @ np.linalg.cholesky(P0).T
    available = np.arange(steps + 1) % sensor_every == 0
    return MonteCarloData(
        model, np.arange(steps + 1) * T, x, np.zeros((runs, steps + 1, 0)), np.zeros((runs, steps + 1, 0)), z, x0, P0,
        np.zeros((runs, 0)), [np.random.SeedSequence(i) for i in range(runs)],
        sensors={"velocity": SensorRecord(zv, available)},
    )  # fmt: skip


def _mean_tolerance(dof: int, samples: int) -> float:
    """4 standard deviations of the mean of ``samples`` independent χ²(dof) (variance 2·dof): a
    consistent Kalman filter's innovations are white, so its NIS at different steps are independent."""
    return 4.0 * np.sqrt(2.0 * dof / samples)


def _share_floor(steps: int) -> float:
    """4 standard deviations below 95 % of ``steps`` independent steps, each inside with p = 0.95."""
    return 0.95 - 4.0 * np.sqrt(0.95 * 0.05 / steps)


def test_a_consistent_kalman_filters_groups_are_chi_square_of_their_size():
    """Positions and their sum (correlated through the state and through R) as two primary
    groups, and the velocity sensor at a third of the rate: each group's NIS averages to its size
    and its run average stays in its band; the sensor's only over the steps it reported."""
    rng = np.random.default_rng(4)
    R = random_spd(rng, 3, 0.2)
    C = np.array([[1.0, 0, 0, 0], [0, 1.0, 0, 0], [1.0, 1.0, 0, 0]])
    runs, steps = 200, 60
    data = _problem(R, R, C, {"position": ("z0", "z1"), "sum": ("z2",)}, runs, steps)
    result = run_estimator("srukf", SRUKF(data.model), data, 1e9)
    reported = int(data.sensors["velocity"].available[1:].sum())
    for group, dof, counted in (("position", 2, steps), ("sum", 1, steps), ("velocity", 2, reported)):
        per_run = result.metric_values[f"nis_{group}"]
        assert abs(per_run.mean() - dof) <= _mean_tolerance(dof, runs * counted), group
        assert result.metric_values[f"nis_in_band_{group}"] >= _share_floor(counted), group


def test_an_over_confident_r_on_one_group_leaves_its_band_and_no_other():
    """Two decoupled coordinates (x and y, each with its velocity) measured as two groups; the
    filter takes y's noise variance 4× too small. That group's run-averaged NIS is then about
    (P⁻ + r)/(P⁻ + r/4) > 1, above its band; the first group, whose estimate the wrong R cannot
    reach (no cross-covariance), stays χ²(1) and in its band."""
    runs, steps, r = 200, 60, 0.2
    R_true = r * np.eye(2)
    R_filter = np.diag([r, r / 4])
    groups = {"first": ("z0",), "second": ("z1",)}
    data = _problem(R_true, R_filter, np.eye(2, 4), groups, runs, steps, coupled=False)
    result = run_estimator("srukf", SRUKF(data.model), data, 1e9)
    first, second = result.metric_values["nis_first"], result.metric_values["nis_second"]
    assert abs(first.mean() - 1.0) <= _mean_tolerance(1, runs * steps)
    assert result.metric_values["nis_in_band_first"] >= _share_floor(steps)
    _, upper = chi2_band(1, runs)
    assert second.mean() > upper + _mean_tolerance(1, runs)
    assert result.metric_values["nis_in_band_second"] < 1.0 - _share_floor(steps)


@pytest.mark.slow
def test_an_estimator_without_innovations_gives_nan_not_a_crash():
    data = _problem(np.eye(2), np.eye(2), np.eye(2, 4), {"first": ("z0",), "second": ("z1",)}, runs=3, steps=6)
    data.model.sensors = {}  # particle filters take no further sensors
    data = replace(data, sensors={})
    result = run_estimator("pf", BootstrapPF(data.model, particles=50), data, 1e9)
    for group in ("first", "second"):
        assert np.isnan(result.metric_values[f"nis_{group}"]).all()
        assert np.isnan(result.metric_values[f"nis_in_band_{group}"])
    overview = GroupNIS().overview(result, data.model)
    assert set(overview) == {f"nis{s}_{g}" for g in ("first", "second") for s in ("", "_in_band")}
    assert all(np.isnan(v) for v in overview.values())


def test_a_model_without_a_primary_measurement_reports_no_whole_measurement_nis():
    """m = 0 (the INS: every measurement is a sensor): the primary NIS of zero components is no
    statistic, so ``mean_nis`` and ``nis_in_band`` are NaN, not 0; the sensor's group is judged."""
    data = _problem(np.zeros((0, 0)), np.zeros((0, 0)), np.zeros((0, 4)), {}, runs=3, steps=6)
    result = run_estimator("srukf", SRUKF(data.model), data, 1e9)
    overview = NIS().overview(result, data.model)
    assert np.isnan(overview["mean_nis"]) and np.isnan(overview["nis_in_band"])
    assert np.isnan(NIS().values(result, data.model)["mean_nis"]).all()
    assert set(measurement_groups(data.model)) == {"velocity"}
    assert np.isfinite(result.metric_values["nis_velocity"]).all()
