"""Replay behaviours a single-point bug breaks without any other test noticing.

- A ULog topic logged by several instances (``multi_id``: two magnetometers, two GPS receivers)
  is read from instance 0, whatever the order of the instances in the file: every topic of a small
  constructed log (both message layouts, every magnetometer and GPS topic the reader knows) gets
  two more instances with other values, listed before and after instance 0, and the flight log
  read from it equals the one read from instance 0 alone.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from quadest.replay.ulog import flight_log_from
from test_replay import _fake_log, _FakeULog, _Topic

LOGS = {
    "older": ("older", "vehicle_magnetometer", None),
    "vehicle_magnetometer+vehicle_gps_position": ("current", "vehicle_magnetometer", "vehicle_gps_position"),
    "sensor_mag+sensor_gps": ("current", "sensor_mag", "sensor_gps"),
}


def other_instance(topic: _Topic, multi_id: int) -> _Topic:
    """The same topic from another device: the same times, every other field changed."""
    data = {k: (v if "timestamp" in k else v + 10.0 * multi_id) for k, v in topic.data.items()}
    return _Topic(topic.name, data, multi_id)


@pytest.mark.parametrize("log", LOGS)
def test_a_topic_logged_by_several_instances_is_read_from_instance_0(log):
    single = _fake_log(*LOGS[log])[0]
    several = []
    for topic in single.data_list:
        several += [other_instance(topic, 1), topic, other_instance(topic, 2)]
    expected, got = flight_log_from(single), flight_log_from(_FakeULog(several))
    for field in dataclasses.fields(expected):
        a, b = getattr(expected, field.name), getattr(got, field.name)
        if isinstance(a, np.ndarray):
            np.testing.assert_array_equal(b, a, err_msg=field.name)
        else:
            assert b == a, field.name


def test_the_replays_magnetometer_r_uses_the_magnetometers_own_sample_period(monkeypatch):
    """A log whose magnetometer runs at 25 Hz, replayed at 100 Hz: the white part of ``R_mag`` is
    σ_c² / 0.04 s (the drift's part is computed alone and taken off), a quarter of what the
    filter's step would give."""
    import quadest.replay.data as replay_data
    from helpers import compose_settings

    log = flight_log_from(_fake_log("current", "vehicle_magnetometer", "vehicle_gps_position")[0])
    log = dataclasses.replace(log, mag_time=log.mag_time[::4], mag=log.mag[::4])
    mag_period = float(np.median(np.diff(log.mag_time)))
    assert mag_period == pytest.approx(0.04, rel=1e-9)
    monkeypatch.setattr(replay_data, "read_flight_log", lambda path: log)
    settings = compose_settings(["experiment=px4_replay", "duration=0.8", "source.warmup=0.1"])
    assert settings.sample_period == pytest.approx(0.01)
    data = replay_data.build_replay_data(settings)
    m = settings.model
    duration = float(data.time[-1] - data.time[0])
    drift = float(m.magnetometer.bias_random_walk) ** 2 * duration / 2.0
    white = data.model.R_mag / float(m.measurement_noise_inflation) - drift * np.eye(3)
    np.testing.assert_allclose(white, float(m.magnetometer.white_noise) ** 2 / mag_period * np.eye(3), rtol=1e-12)
