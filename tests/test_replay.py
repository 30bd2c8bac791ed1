"""The PX4 log replay: reader (both message layouts, missing topics), time alignment, a
complementary-filter sanity anchor on the shipped log, and the replay job end to end."""

from __future__ import annotations

import itertools
from dataclasses import dataclass, replace

import numpy as np
import pandas as pd
import pytest
from scipy.spatial.transform import Rotation

from quadest.errors import ConfigError
from quadest.replay.align import align
from quadest.replay.data import shipped_log
from quadest.replay.ulog import RELATIVE_TIMESTAMP_INVALID, FlightLog, flight_log_from, read_flight_log

# --- a small fake log, shaped like pyulog.ULog (pyulog 1.3 has no writer) ---


@dataclass
class _Topic:
    name: str
    data: dict
    multi_id: int = 0


@dataclass
class _FakeULog:
    data_list: list


def _vector(field: str, values: np.ndarray) -> dict:
    return {f"{field}[{i}]": values[:, i] for i in range(values.shape[1])}


def _fake_log(layout: str, mag_topic: str = "vehicle_magnetometer", gps_topic: str | None = "vehicle_gps_position"):
    """IMU at 250 Hz for 1 s from t = 10 s, magnetometer at 100 Hz, attitude at 50 Hz."""
    t_imu = 10_000_000 + 4000 * np.arange(250)
    gyro, accel = np.tile([0.1, -0.2, 0.3], (250, 1)), np.tile([0.0, 0.0, -9.81], (250, 1))
    sc = {"timestamp": t_imu, **_vector("gyro_rad", gyro), **_vector("accelerometer_m_s2", accel)}
    sc["accelerometer_timestamp_relative"] = np.zeros(250, dtype=np.int64)
    mag_times = 10_001_000 + 10_000 * np.arange(100)
    mag = np.column_stack([0.2 + 1e-3 * np.arange(100), np.zeros(100), 0.4 * np.ones(100)])
    topics = []
    if layout == "older":  # the latest magnetometer sample repeated in every sensor_combined message
        latest = np.searchsorted(mag_times, t_imu, side="right") - 1
        has = latest >= 0
        rel = np.where(has, mag_times[np.maximum(latest, 0)] - t_imu, RELATIVE_TIMESTAMP_INVALID)
        sc.update(_vector("magnetometer_ga", np.where(has[:, None], mag[np.maximum(latest, 0)], 0.0)))
        sc["magnetometer_timestamp_relative"] = rel
    elif mag_topic == "vehicle_magnetometer":
        topics.append(_Topic(mag_topic, {"timestamp": mag_times + 300, "timestamp_sample": mag_times,
                                         **_vector("magnetometer_ga", mag)}))  # fmt: skip
    elif mag_topic == "sensor_mag":
        topics.append(_Topic(mag_topic, {"timestamp": mag_times, "x": mag[:, 0], "y": mag[:, 1], "z": mag[:, 2]}))
    topics.append(_Topic("sensor_combined", sc))
    t_att = 10_000_000 + 20_000 * np.arange(50)
    q = np.tile([2.0, 0.0, 0.0, 0.0], (50, 1))  # not unit: the reader normalises
    topics.append(_Topic("vehicle_attitude", {"timestamp": t_att, **_vector("q", q)}))
    if gps_topic is not None:
        t_gps = 10_000_000 + 200_000 * np.arange(5)
        vel = {f"vel_{a}_m_s": np.full(5, v) for a, v in zip("ned", (1.0, 2.0, 3.0), strict=True)}
        topics.append(_Topic(gps_topic, {"timestamp": t_gps, **vel}))
    return _FakeULog(topics), mag_times * 1e-6, mag


def test_older_layout_takes_each_magnetometer_sample_once_from_sensor_combined():
    ulog, mag_times, mag = _fake_log("older", gps_topic=None)
    log = flight_log_from(ulog, "old.ulg")
    assert log.layout == "older"
    first = np.searchsorted(mag_times, log.imu_time[0])  # samples before the first IMU message are not logged
    np.testing.assert_allclose(log.mag_time, mag_times[first : np.searchsorted(mag_times, log.imu_time[-1], "right")])
    np.testing.assert_allclose(log.mag, mag[first : first + len(log.mag_time)])
    np.testing.assert_allclose(log.imu_time[:2], [10.0, 10.004])
    np.testing.assert_allclose(log.reference_q, np.tile([1.0, 0.0, 0.0, 0.0], (50, 1)))
    assert log.gps_time is None


@pytest.mark.parametrize("mag_topic", ["vehicle_magnetometer", "sensor_mag"])
@pytest.mark.parametrize("gps_topic", ["vehicle_gps_position", "sensor_gps"])
def test_current_layout_reads_the_magnetometer_and_gps_topics(mag_topic, gps_topic):
    ulog, mag_times, mag = _fake_log("current", mag_topic, gps_topic)
    log = flight_log_from(ulog, "new.ulg")
    assert log.layout == "current"
    np.testing.assert_allclose(log.mag_time, mag_times)  # timestamp_sample where the topic has it
    np.testing.assert_allclose(log.mag, mag)
    np.testing.assert_allclose(log.gps_velocity, np.tile([1.0, 2.0, 3.0], (5, 1)))


@pytest.mark.parametrize(
    ("drop", "named"),
    [
        ("vehicle_attitude", "vehicle_attitude"),
        ("sensor_combined", "sensor_combined"),
        ("vehicle_magnetometer", "vehicle_magnetometer or sensor_mag"),
    ],
)
def test_a_log_without_a_needed_topic_fails_with_one_line_naming_it(drop, named):
    ulog, _, _ = _fake_log("current", gps_topic=None)
    ulog.data_list = [t for t in ulog.data_list if t.name != drop]
    with pytest.raises(ConfigError) as err:
        flight_log_from(ulog, "/logs/flight.ulg")
    message = str(err.value)
    assert "\n" not in message and named in message and "/logs/flight.ulg" in message


def test_a_file_that_is_not_a_ulog_fails_with_one_line(tmp_path):
    bad = tmp_path / "not_a_log.ulg"
    bad.write_bytes(b"hello")
    for path in (bad, tmp_path / "missing.ulg"):
        with pytest.raises(ConfigError) as err:
            read_flight_log(path)
        assert "\n" not in str(err.value) and str(path) in str(err.value)


# --- alignment ---


def _log(imu_time, gyro, mag_time=None, ref_time=None, ref_q=None) -> FlightLog:
    n = len(imu_time)
    mag_time = imu_time[::3] if mag_time is None else mag_time
    ref_time = imu_time if ref_time is None else ref_time
    ref_q = np.tile([1.0, 0, 0, 0], (len(ref_time), 1)) if ref_q is None else ref_q
    return FlightLog("x.ulg", "older", imu_time, gyro, imu_time, np.tile([0, 0, -9.81], (n, 1)), mag_time,
                     np.tile([0.2, 0.0, 0.4], (len(mag_time), 1)), ref_time, ref_q)  # fmt: skip


def test_gyro_input_is_the_exact_mean_rate_over_each_step():
    """Irregular samples (jitter, a 40 ms dropout), each the mean rate over the interval ending at
    it: the input of step k must be (angle(t_{k+1}) - angle(t_k)) / T, computed here by hand."""
    rng = np.random.default_rng(3)
    dt = 0.004 + 0.0004 * rng.standard_normal(400)
    dt[200] = 0.040
    t = 1.0 + np.cumsum(dt)
    rates = np.column_stack([np.sin(t), np.cos(3 * t), 0.1 * t])
    aligned = align(_log(t, rates), period=0.01)

    def angle(s):  # piecewise-constant rate: the sample at t_i holds on (t_{i-1}, t_i]; 0 at t_0
        i = np.searchsorted(t, s)  # the sample whose interval contains s
        if i == 0:
            return np.zeros(3)
        done = np.sum(rates[1:i] * np.diff(t[:i])[:, None], axis=0)
        return done + rates[i] * (s - t[i - 1])

    grid = aligned.time + t[0]
    expected = np.array([(angle(b) - angle(a)) / 0.01 for a, b in itertools.pairwise(grid)])
    np.testing.assert_allclose(aligned.gyro[:-1], expected, atol=1e-12)
    assert aligned.gaps == 1 and aligned.longest_gap == pytest.approx(0.040)


def test_magnetometer_is_available_at_the_step_after_each_sample():
    t = 2.0 + 0.004 * np.arange(100)
    mag_time = np.array([2.0, 2.013, 2.0135, 2.047])
    aligned = align(_log(t, np.zeros((100, 3)), mag_time=mag_time), period=0.01)
    assert list(np.flatnonzero(aligned.mag_available)) == [0, 2, 5]  # 2.013 and 2.0135 both land at step 2


def test_reference_slerp_reproduces_a_constant_rate_rotation():
    """Slerp is exact for a rotation at constant rate: the reference at the grid times must be
    exp(ω t) whatever the (irregular) times of PX4's samples."""
    t = np.cumsum(np.full(300, 0.004))
    ref_t = np.sort(np.concatenate([[t[0]], t[0] + np.random.default_rng(1).uniform(0, t[-1] - t[0], 80), [t[-1]]]))
    w = np.array([0.3, -0.5, 1.1])
    ref_q = Rotation.from_rotvec(ref_t[:, None] * w).as_quat()[:, [3, 0, 1, 2]]
    aligned = align(_log(t, np.zeros((300, 3)), ref_time=ref_t, ref_q=ref_q), period=0.01)
    expected = Rotation.from_rotvec((aligned.time + t[0])[:, None] * w).as_quat()[:, [3, 0, 1, 2]]
    expected *= np.sign(expected[:, :1])
    np.testing.assert_allclose(aligned.reference_q, expected, atol=1e-12)


# --- the shipped log ---


@pytest.fixture(scope="module")
def shipped():
    return read_flight_log(shipped_log())


def _complementary_filter(gyro, accel, T, k_p=1.0, k_i=0.5):
    """Mahony's explicit complementary filter (Mahony et al. 2008, eq. 32) on gyro and
    accelerometer only, written with scipy's rotations (independent of quadest's quaternions).
    Returns roll and pitch (deg) at every step. Gains 5x PX4's ATT_W_ACC = 0.2 (integral 0.5 vs
    0.1): it starts with zero bias, PX4's bias had converged before the log began."""
    f = accel[0]
    q = Rotation.from_euler("ZYX", [0.0, np.arctan2(f[0], np.hypot(f[1], f[2])), np.arctan2(-f[1], -f[2])])
    bias = np.zeros(3)
    out = np.empty((len(gyro), 2))
    out[0] = q.as_euler("ZYX", degrees=True)[[2, 1]]
    for k in range(1, len(gyro)):
        down_body = q.inv().apply([0.0, 0.0, 1.0])
        a = accel[k - 1]
        correction = np.cross(-a / np.linalg.norm(a), down_body)  # Mahony's v_measured x v_estimated; "down" is -a
        bias += k_i * correction * T
        q = q * Rotation.from_rotvec((gyro[k - 1] + bias + k_p * correction) * T)
        out[k] = q.as_euler("ZYX", degrees=True)[[2, 1]]
    return out


def test_complementary_filter_anchor_agrees_with_px4_within_a_tenth_of_a_degree(shipped):
    """Sanity anchor of the reader and the alignment: a complementary filter on the log's gyro and
    accelerometer comes within 0.1 deg RMS of PX4's roll and pitch after 5 s. A frame or sign
    error (swapped axes, a flipped accelerometer, the reference taken as earth→body) breaks it; a
    gyro input lagging one step does not (the log is at rest after 6 s): the exact-mean test above
    guards that."""
    T = 0.01
    aligned = align(shipped, T)
    ours = _complementary_filter(aligned.gyro, aligned.accel, T)
    px4 = Rotation.from_quat(aligned.reference_q[:, [1, 2, 3, 0]]).as_euler("ZYX", degrees=True)[:, [2, 1]]
    after = aligned.time >= 5.0
    rms = np.sqrt(np.mean((ours[after] - px4[after]) ** 2, axis=0))
    assert np.all(rms < 0.1), rms


def test_shipped_log_is_the_older_layout(shipped):
    assert shipped.layout == "older"
    assert shipped.imu_time[-1] - shipped.imu_time[0] == pytest.approx(68.9, abs=0.1)
    assert np.allclose(np.linalg.norm(shipped.reference_q, axis=1), 1.0)


def test_start_outside_the_log_is_refused(shipped):
    with pytest.raises(ConfigError, match=r"source\.start"):
        align(shipped, 0.01, start=1000.0)


def test_a_window_shorter_than_one_step_is_refused(shipped):
    short = replace(shipped, imu_time=shipped.imu_time[:1], gyro=shipped.gyro[:1])
    for log, duration in ((short, float("inf")), (shipped, 0.005)):
        with pytest.raises(ConfigError, match=r"source\.start"):
            align(log, 0.01, duration=duration)


# --- the job ---


def _replay_config(overrides: list[str]):
    from hydra import compose, initialize_config_dir

    from quadest.app.schema import register_schemas
    from quadest.config.paths import config_dir

    register_schemas()
    with initialize_config_dir(config_dir(), version_base="1.3"):
        return compose("config", ["experiment=px4_replay", *overrides])


@pytest.mark.parametrize(
    ("override", "key"),
    [("runs=3", "runs"), ("source.path=/no/such.ulg", "source.path"), ("source.name=csv", "source.name"),
     ("source.warmup=-1", "source.warmup")],
)  # fmt: skip
def test_bad_replay_settings_fail_validation_with_one_line(override, key):
    from quadest.app.validate import validate

    with pytest.raises(ConfigError) as err:
        validate(_replay_config([override]))
    assert err.value.key == key and "\n" not in str(err.value)


@pytest.fixture(scope="module")
def replay_outputs(tmp_path_factory):
    from quadest.app.job import run_job

    out = tmp_path_factory.mktemp("px4_replay")
    summary = run_job(_replay_config(["progress=false", "workers=1"]), out, ["experiment=px4_replay"])
    return out, summary


@pytest.mark.integration
@pytest.mark.slow
def test_replay_meets_the_goal_and_is_no_further_from_px4_than_the_ahrs_filters(replay_outputs):
    """The replay's goal on the shipped log (docs/replay.md): roll and pitch within 0.5 deg RMS of PX4's estimate
    after the first 5 s, and no further from it than Madgwick, Mahony and the ahrs EKF."""
    out, _ = replay_outputs
    s = pd.read_csv(out / "rmse_summary.csv").set_index(["estimator", "state"])["rmse_mean"]
    for angle in ("roll", "pitch"):
        assert s["mekf", angle] < 0.5
        for anchor in ("madgwick", "mahony", "ahrs_ekf"):
            assert s["mekf", angle] <= s[anchor, angle], (angle, anchor, s.to_dict())


@pytest.mark.integration
@pytest.mark.slow
def test_replay_writes_the_outputs_of_every_job_with_differences_to_px4(replay_outputs):
    out, summary = replay_outputs
    tables = ("metrics.csv", "rmse_summary.csv", "rmse_table.md", "paired_comparison.csv", "summary.json")
    figures = ("figures/attitude_vs_px4.png", "figures/difference_to_px4.png")
    for name in (*tables, "timeseries.npz", "config.yaml", *figures):
        assert (out / name).is_file(), name
    table = pd.read_csv(out / "rmse_summary.csv")
    assert set(table["state"]) == {"roll", "pitch", "yaw", "attitude"} and set(table["unit"]) == {"deg"}
    assert set(table["quantity"]) == {"difference to PX4"} and table["pcrlb"].isna().all()
    # the attitude row: the one rotation angle 2 atan2(|v|, |w|) of q_ref* ⊗ q_est, the product written
    # out here; and the median |roll difference| from the saved angles, over the compared window
    series = np.load(out / "timeseries.npz")
    window = series["time"] >= series["time"][0] + summary["compared_from"]
    (w1, x1, y1, z1), (w2, x2, y2, z2) = series["reference"][window, :4].T, series["mekf/estimate"][0][window, :4].T
    w = w1 * w2 + x1 * x2 + y1 * y2 + z1 * z2
    v = np.stack([w1 * x2 - x1 * w2 - y1 * z2 + z1 * y2, w1 * y2 - y1 * w2 - z1 * x2 + x1 * z2,
                  w1 * z2 - z1 * w2 - x1 * y2 + y1 * x2])  # fmt: skip
    angle = np.degrees(2 * np.arctan2(np.linalg.norm(v, axis=0), np.abs(w)))
    rows = table.set_index(["estimator", "state"])
    assert rows.loc[("mekf", "attitude"), "rmse_mean"] == pytest.approx(np.sqrt(np.mean(angle**2)), rel=1e-6)
    roll = (series["mekf/angles_deg"][window, 0] - series["reference_angles_deg"][window, 0] + 180) % 360 - 180
    assert rows.loc[("mekf", "roll"), "abs_error_median"] == pytest.approx(np.median(np.abs(roll)), rel=1e-9)
    metrics = pd.read_csv(out / "metrics.csv")
    assert (metrics["reference"] == "PX4 onboard estimate").all() and metrics["mean_nees"].isna().all()
    assert not metrics["diverged"].any()
    assert summary["reference"] == "PX4 onboard estimate" and "not reported" in summary["_caption"]
    assert all(e["mean_nees"] is None for e in summary["estimators"].values())


@pytest.fixture(scope="module")
def smoothed_replay_outputs(tmp_path_factory):
    from quadest.app.job import run_job

    out = tmp_path_factory.mktemp("px4_replay_smoothed")
    overrides = ["experiment=px4_replay_smoothed", "duration=20", "progress=false", "workers=1", "cache.enabled=false"]
    return out, run_job(_replay_config(overrides), out, overrides)


@pytest.mark.integration
@pytest.mark.slow
def test_smoothed_replay_writes_every_rows_difference_to_the_offline_reference(smoothed_replay_outputs):
    """The offline reference's table (docs/replay.md): one line per other row (PX4's estimate
    included) and angle. Two independent checks: PX4's RMS difference to the smoothed MEKF is the
    smoothed row's "difference to PX4" of rmse_summary.csv, computed by another path (the Euler
    differences of attitude_errors_deg, the other way round); and the filter's own difference is
    the RMS of its saved angles minus the smoothed row's over the compared window, wrapped."""
    out, summary = smoothed_replay_outputs
    table = pd.read_csv(out / "difference_to_smoothed.csv")
    assert set(table["reference"]) == {"mekf+smoothed"}
    rows = {"mekf", "madgwick", "mahony", "ahrs_ekf", "PX4 onboard estimate"}
    assert set(table["estimator"]) == rows and len(table) == 3 * len(rows)
    to_px4 = pd.read_csv(out / "rmse_summary.csv").set_index(["estimator", "state"])["rmse_mean"]
    diff = table.set_index(["estimator", "state"])["rms_difference"]
    for angle in ("roll", "pitch", "yaw"):
        np.testing.assert_allclose(diff["PX4 onboard estimate", angle], to_px4["mekf+smoothed", angle], rtol=1e-9)
    series = np.load(out / "timeseries.npz")
    window = series["time"] >= series["time"][0] + summary["compared_from"]
    wrapped = (series["mekf/angles_deg"] - series["mekf+smoothed/angles_deg"] + 180.0) % 360.0 - 180.0
    rms = np.sqrt(np.mean(wrapped[window] ** 2, axis=0))
    np.testing.assert_allclose([diff["mekf", a] for a in ("roll", "pitch", "yaw")], rms, rtol=1e-12)
    assert summary["difference_to_smoothed"]["mekf+smoothed"]["mekf"]["yaw"] == pytest.approx(diff["mekf", "yaw"])
    assert (out / "figures" / "difference_to_smoothed.png").is_file()
    assert "RMS difference to mekf+smoothed" in summary["_after_table"]


@pytest.mark.integration
@pytest.mark.slow
def test_a_replay_without_a_smoother_writes_no_offline_reference(replay_outputs):
    out, summary = replay_outputs
    assert not (out / "difference_to_smoothed.csv").exists() and "difference_to_smoothed" not in summary
