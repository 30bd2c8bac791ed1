"""The filterpy baselines evaluate the model once per step for the whole batch: same numbers as the
per-run evaluation, run for run, including runs that fail."""

from __future__ import annotations

import numpy as np
import pytest

from helpers import compose_settings
from quadest.estimators.base import PerRunAdapter
from quadest.estimators.filterpy_ekf import BatchedFilterpyEKF, FilterpyEKF
from quadest.estimators.filterpy_ukf import BatchedFilterpyUKF, FilterpyUKF
from quadest.simulation.registry import build_data

BASELINES = {
    "ekf": (lambda m: PerRunAdapter(m, FilterpyEKF), BatchedFilterpyEKF),
    "ukf": (lambda m: PerRunAdapter(m, FilterpyUKF, alpha=1e-3), lambda m: BatchedFilterpyUKF(m, alpha=1e-3)),
}


@pytest.mark.parametrize("baseline", sorted(BASELINES))
@pytest.mark.parametrize("formulation", ["thesis", "augmented"])
@pytest.mark.slow
def test_batched_model_evaluation_gives_the_per_run_numbers(formulation, baseline):
    """Both adapters run one filterpy filter per run; only where the model (f, h and, for the
    EKF, F, H) is evaluated differs, and the model gives the same floats for one run's rows as for
    the batch's, so the numbers are bit-identical (exact equality). Run 1 starts from a NaN mean
    and run 2 (UKF) from a P0 with no Cholesky factor: they must fail in both and leave the other
    runs untouched."""
    data = build_data(compose_settings([f"model.formulation={formulation}", "runs=4", "duration=1.0"]))
    m = data.model
    x0 = data.x0.copy()
    x0[1] = np.nan
    P0 = np.broadcast_to(data.P0, (4, m.n, m.n)).copy()
    if baseline == "ukf":
        P0[2, 0, 0] = -1.0
    make_per_run, make_batched = BASELINES[baseline]
    per_run, batched = make_per_run(m), make_batched(m)
    assert batched.capabilities == per_run.capabilities == {"innovation", "smoothing"}
    companion = data.companion0
    for est in (per_run, batched):
        est.initialize(x0, P0)
    for k in range(1, data.time.size):
        u_prev = m.filter_input(data.inputs[:, k - 1], companion)
        for est in (per_run, batched):
            est.predict(u_prev)
        u_now = m.filter_input(data.inputs[:, k], companion)
        for est in (per_run, batched):
            est.update(data.measurements[:, k], u_now)
        for a, b in zip(per_run.innovation(), batched.innovation(), strict=True):
            np.testing.assert_array_equal(b, a)
        np.testing.assert_array_equal(batched.mean, per_run.mean)
        np.testing.assert_array_equal(batched.covariance, per_run.covariance)
        companion = m.companion_step(companion, np.nan_to_num(per_run.mean))
    expected = [False, True, baseline == "ukf", False]
    assert per_run.failed.tolist() == batched.failed.tolist() == expected
    assert per_run.failure_reasons == batched.failure_reasons
    assert np.isfinite(batched.mean[~np.array(expected)]).all()
