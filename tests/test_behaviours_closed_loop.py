"""Closed-loop behaviours a single-point bug breaks without any other test noticing.

- With the estimate fed back (``loop=estimate``), the filter predicts from step k−1 to k with the
  inputs of step k−1 and updates with those of step k, for every closed loop (the quadrotor's and
  seed 003's): the input ``predict`` receives at step k is the one ``update`` received at step
  k−1, the first is the input of the initial sample, and consecutive inputs differ (a loop that
  predicted with step k's input would pass a test on constant inputs).
- Seed 003's state sensor puts the angle σ on the angles and the rate σ on the rates: each of
  the five states it measures gets the σ of its unit, read from the filter model's
  ``state_units``.
"""

from __future__ import annotations

import numpy as np
import pytest

from helpers import compose_config
from quadest.app.job import job_kind
from quadest.app.settings import job_settings
from quadest.config.closed_loop import ClosedLoopConf, StateSensorConf
from quadest.estimators.registry import build_estimator
from quadest.models.seed003_attitude import SLOTS, AttitudeRateModel, measure_states, sensor_std

SHORT = ["runs=2", "duration=0.3", "progress=false", "output.saved_runs=1", "output.figures=false",
         "estimator=[ekf]", "loop=estimate"]  # fmt: skip
LOOPS = {
    "quadrotor": ["scenario=attitude_steps", "scenario.steps=[[0.1,0.0,4.0]]", "scenario.transition_time=0.05"],
    "seed003": ["experiment=seed003_closed_loop", "scenario.takeoff_time=0.0",
                "scenario.steps=[[0.1,0.0,4.0]]", "scenario.transition_time=0.05"],
}  # fmt: skip


@pytest.mark.parametrize("name", LOOPS)
def test_the_closed_loop_filter_predicts_with_the_inputs_of_the_previous_step(name):
    cfg = compose_config([*LOOPS[name], *SHORT])
    job = job_kind(job_settings(cfg))
    loop = job.work(job.make_data()).loop
    est = build_estimator("ekf", dict(cfg.estimator["ekf"]), loop.filter_model())
    predicted, updated = [], []
    predict, update = est.predict, est.update

    def recording_predict(u):
        predicted.append(np.array(u, copy=True))
        predict(u)

    def recording_update(z, u, sensor=None):
        if sensor is None:
            updated.append(np.array(u, copy=True))
        update(z, u) if sensor is None else update(z, u, sensor)

    est.predict, est.update = recording_predict, recording_update
    start = loop.plant()  # the rotor speeds of the initial sample, as each loop reads them
    first = start.encoders() if name == "quadrotor" else start.state[:, 12:16]
    loop.fly_estimator("ekf", est, 1e6, 1)
    assert len(predicted) == len(updated) >= 10
    for k in range(1, len(predicted)):
        np.testing.assert_array_equal(predicted[k], updated[k - 1])
    assert any(not np.array_equal(predicted[k], updated[k]) for k in range(len(predicted)))
    np.testing.assert_array_equal(predicted[0][:, :4], first)


def test_seed003s_state_sensor_puts_the_angle_sigma_on_angles_and_the_rate_sigma_on_rates():
    conf = ClosedLoopConf(state_sensor=StateSensorConf(angle=0.03, rate=0.7))
    std = sensor_std(conf)
    by_unit = {"rad": 0.03, "rad/s": 0.7}
    np.testing.assert_array_equal(std, [by_unit[unit] for unit in AttitudeRateModel.state_units])
    truth, normals = np.zeros((1, 16)), np.zeros((1, 12))
    normals[:, SLOTS] = 1.0
    np.testing.assert_array_equal(measure_states(truth, normals, std)[0], std)
