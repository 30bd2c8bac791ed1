"""The EKF baseline evaluates the model once per step for the whole batch: same numbers as the
per-run evaluation, run for run, including a run that fails."""

from __future__ import annotations

import numpy as np
import pytest

from helpers import compose_config
from quadest.estimators.base import PerRunAdapter
from quadest.estimators.filterpy_ekf import BatchedFilterpyEKF, FilterpyEKF
from quadest.models.registry import build_data


@pytest.mark.parametrize("formulation", ["thesis", "augmented"])
def test_batched_model_evaluation_gives_the_per_run_numbers(formulation):
    """Both adapters run filterpy's EKF per run; only where f, F, h, H are evaluated differs.
    Elementwise model code gives the same floats for one row or many, so the tolerance is a few
    ulps (rtol 1e-12) in case BLAS takes another path for a batch of 3x3 products. Run 1 starts
    from a NaN mean: it must fail in both and leave the other runs untouched."""
    data = build_data(compose_config([f"model.formulation={formulation}", "runs=4", "duration=1.0"]))
    m = data.model
    x0 = data.x0.copy()
    x0[1] = np.nan
    P0 = np.broadcast_to(data.P0, (4, m.n, m.n)).copy()
    per_run, batched = PerRunAdapter(m, FilterpyEKF), BatchedFilterpyEKF(m)
    assert batched.capabilities == per_run.capabilities == {"innovation"}
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
            np.testing.assert_allclose(b, a, rtol=1e-12, atol=0)
        np.testing.assert_allclose(batched.mean, per_run.mean, rtol=1e-12, atol=0)
        np.testing.assert_allclose(batched.covariance, per_run.covariance, rtol=1e-12, atol=0)
        companion = m.companion_step(companion, np.nan_to_num(per_run.mean))
    assert per_run.failed.tolist() == batched.failed.tolist() == [False, True, False, False]
    assert np.isfinite(batched.mean[[0, 2, 3]]).all()
