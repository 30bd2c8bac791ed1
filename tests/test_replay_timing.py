"""Replay timing against the log itself (docs/replay.md).

PX4 documents how each sample is timed (``msg/SensorCombined.msg``): ``timestamp`` is the gyro's
time (µs since boot), ``timestamp + accelerometer_timestamp_relative`` the accelerometer's and, in
the older layout, ``timestamp + magnetometer_timestamp_relative`` the magnetometer's, a relative
value of ``RELATIVE_TIMESTAMP_INVALID`` (0x7fffffff) meaning "no sample"; a topic with
``timestamp_sample`` is timed by it. Here the times of every replayed sensor are compared with
those raw fields, read by pyulog and combined in this file:

- on the shipped log as it is;
- on a copy written with pyulog in which every relative-timestamp field the replay reads holds
  other offsets: the shipped log's accelerometer offsets are all zero, so only there would a reader
  that drops one go unnoticed. The copy is also replayed end to end: the accelerometer measurement
  at each grid time is the log's accelerometer interpolated at its PX4 times.

Times are compared to 1 ns: the log's resolution is 1 µs and converting µs to seconds rounds by
less than 1e-13 s at the log's 10²–10³ s of boot time.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest
from pyulog import ULog

from helpers import compose_config
from quadest.app.settings import data_settings
from quadest.replay.data import build_replay_data, shipped_log
from quadest.replay.ulog import RELATIVE_TIMESTAMP_INVALID, flight_log_from, read_flight_log

TOPICS = ["sensor_combined", "vehicle_attitude"]
ONE_NS = 1e-9
RELATIVE_FIELDS = {
    "accelerometer_timestamp_relative": "accel_time",
    "magnetometer_timestamp_relative": "mag_time",
    "baro_timestamp_relative": None,  # the replay uses no barometer
}
"""Every relative-timestamp field of ``sensor_combined`` and the replayed times it sets."""


def raw_topics(ulog) -> dict[str, dict[str, np.ndarray]]:
    return {d.name: d.data for d in ulog.data_list if d.multi_id == 0}


def px4_times(topics: dict[str, dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """Seconds of each replayed sensor's samples, by PX4's rules (module docstring)."""
    sc = {k: np.asarray(v, dtype=np.int64) for k, v in topics["sensor_combined"].items()}
    ts = sc["timestamp"]
    accel_valid = sc["accelerometer_timestamp_relative"] != RELATIVE_TIMESTAMP_INVALID
    mag_valid = sc["magnetometer_timestamp_relative"] != RELATIVE_TIMESTAMP_INVALID
    mag_stamps = (ts + sc["magnetometer_timestamp_relative"])[mag_valid]
    assert np.all(np.diff(mag_stamps) >= 0), "the magnetometer's samples come in time order"
    attitude = topics["vehicle_attitude"]
    reference = attitude.get("timestamp_sample", attitude["timestamp"])
    return {
        "imu_time": ts / 1e6,
        "accel_time": (ts + sc["accelerometer_timestamp_relative"])[accel_valid] / 1e6,
        "mag_time": np.unique(mag_stamps) / 1e6,  # PX4 repeats the latest sample until a new one: each once
        "reference_time": np.asarray(reference, dtype=np.int64) / 1e6,
    }


def assert_times_match(log, expected: dict[str, np.ndarray]) -> None:
    for name, times in expected.items():
        got = getattr(log, name)
        assert got.shape == times.shape, name
        np.testing.assert_allclose(got, times, rtol=0, atol=ONE_NS, err_msg=name)


@pytest.fixture(scope="module")
def shipped_topics():
    return raw_topics(ULog(str(shipped_log()), TOPICS))


def test_every_relative_timestamp_field_of_the_log_is_accounted_for(shipped_topics):
    """A relative field that times samples in this log is one the replay reads; the barometer's
    holds no sample in the shipped log."""
    fields = {k for k in shipped_topics["sensor_combined"] if k.endswith("_timestamp_relative")}
    assert fields == set(RELATIVE_FIELDS)
    for field, target in RELATIVE_FIELDS.items():
        if target is None:
            assert np.all(shipped_topics["sensor_combined"][field] == RELATIVE_TIMESTAMP_INVALID), field


def test_the_shipped_log_is_timed_by_pyulogs_raw_fields(shipped_topics):
    assert_times_match(read_flight_log(shipped_log()), px4_times(shipped_topics))


@pytest.fixture(scope="module")
def shifted_log(tmp_path_factory):
    """The shipped log with other relative offsets, written by pyulog: the accelerometer's vary
    from row to row over ±1 ms (less than half the rows' 3.9 ms spacing, so they stay in time
    order) and every 97th row has none (``RELATIVE_TIMESTAMP_INVALID``: no accelerometer sample in
    that row, as PX4 logs a gyro sample without one), the magnetometer's move by −1.5 ms (a constant, so a sample
    repeated over several rows stays one sample)."""
    ulog = ULog(str(shipped_log()), TOPICS)
    sc = next(d for d in ulog.data_list if d.name == "sensor_combined").data
    rows = sc["timestamp"].size
    sc["accelerometer_timestamp_relative"][:] = np.random.default_rng(7).integers(-1000, 1001, rows)
    sc["accelerometer_timestamp_relative"][::97] = RELATIVE_TIMESTAMP_INVALID
    mag = sc["magnetometer_timestamp_relative"]
    mag[mag != RELATIVE_TIMESTAMP_INVALID] -= 1500
    path = tmp_path_factory.mktemp("shifted") / "shifted.ulg"
    ulog.write_ulog(str(path))
    return path


def test_every_relative_timestamp_field_times_its_sensor(shifted_log, shipped_topics):
    """On the copy, every replayed time equals the raw fields combined, and every relative field
    moved its sensor's times (so a reader ignoring one would fail above)."""
    topics = raw_topics(ULog(str(shifted_log), TOPICS))
    log = read_flight_log(shifted_log)
    assert_times_match(log, px4_times(topics))
    unshifted = px4_times(shipped_topics)
    for field, target in RELATIVE_FIELDS.items():
        if target is not None:
            got, before = getattr(log, target), unshifted[target]
            assert got.shape != before.shape or np.abs(got - before).max() >= 1e-3, f"{field} did not move {target}"


def test_a_topics_timestamp_sample_times_it(shipped_topics):
    """A topic that logs ``timestamp_sample`` (current PX4) is timed by it, not by when it was
    published: the reference attitude here, 3–4 ms before its ``timestamp``."""

    @dataclass
    class Item:
        name: str
        data: dict
        multi_id: int = 0

    topics = {name: dict(data) for name, data in shipped_topics.items()}
    stamps = topics["vehicle_attitude"]["timestamp"]
    topics["vehicle_attitude"]["timestamp_sample"] = stamps - 3000 - np.arange(stamps.size) % 1000

    @dataclass
    class Log:
        data_list: list

    log = flight_log_from(Log([Item(name, data) for name, data in topics.items()]))
    assert_times_match(log, px4_times(topics))


def test_the_replay_measures_the_accelerometer_at_its_px4_times(shifted_log):
    """End to end on the copy: the replay's accelerometer at grid time t_k is the log's
    accelerometer linearly interpolated at ``t_k`` on its PX4 times (docs/replay.md). Values agree
    to 1e-9 m/s²: the only difference allowed is the rounding of the times (below 1e-13 s) times the
    largest slope of the log's accelerometer (below 1e5 m/s³)."""
    cfg = compose_config(["experiment=px4_replay", f"source.path={shifted_log}", "duration=5.0", "progress=false"])
    data = build_replay_data(data_settings(cfg))
    topics = raw_topics(ULog(str(shifted_log), TOPICS))
    times = px4_times(topics)
    sc = topics["sensor_combined"]
    valid = sc["accelerometer_timestamp_relative"] != RELATIVE_TIMESTAMP_INVALID
    accel = np.column_stack([sc[f"accelerometer_m_s2[{i}]"] for i in range(3)]).astype(float)[valid]
    slope = np.abs(np.diff(accel, axis=0) / np.diff(times["accel_time"])[:, None]).max()
    assert np.all(np.diff(times["accel_time"]) > 0) and slope < 1e5
    t0 = max(times["imu_time"][0], times["accel_time"][0], times["reference_time"][0])
    grid = t0 + data.time  # data.time counts from t0
    expected = np.column_stack([np.interp(grid, times["accel_time"], accel[:, i]) for i in range(3)])
    np.testing.assert_allclose(data.measurements[0], expected, rtol=0, atol=1e-9)
