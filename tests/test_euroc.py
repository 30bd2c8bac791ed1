"""EuRoC-layout folders as a data source (quadest/simulation/euroc.py, docs/models.md): the reader
returns what was written, interpolates the reference between its samples exactly where the
interpolant is exact, names its frame (the INS flies the reference with the reader's IMU), refuses a
bad folder in one line before any work, and ``quadest`` runs the INS on such a folder."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest

from euroc_folder import (
    IMU_HEADER,
    REFERENCE_HEADER,
    imu_rows,
    motion,
    reference_rows,
    seconds,
    stamps,
    write_euroc,
    write_flight,
)
from helpers import compose_config, compose_settings
from quadest.app.settings import data_key
from quadest.errors import ConfigError
from quadest.evaluation.trajectory_errors import write_trajectory_errors
from quadest.numerics import quaternion as quat
from quadest.simulation.attitude_data import build_attitude_data
from quadest.simulation.euroc import read_euroc
from quadest.simulation.ins_data import build_ins_data, validate_ins
from quadest.simulation.recorded import read_recordings

PERIOD_NS = 5_000_000  # EuRoC's IMU: 200 Hz
ROUND_OFF = 1e-12  # values of order 1 after a few float operations


def _settings(folder, period=0.005, duration=20.0, aiding="[]"):
    timing = [f"sample_period={period}", f"duration={duration}"]
    return compose_settings(["model=ins", "runs=1", f"model.recording={folder}", f"model.aiding={aiding}", *timing])


def test_the_reader_returns_the_written_reference_and_drops_the_imu_outside_its_span(tmp_path):
    imu_stamps = stamps(PERIOD_NS, 60)
    ref_stamps = imu_stamps[10:-7]
    write_euroc(tmp_path, imu_stamps, imu_rows(seconds(imu_stamps)), ref_stamps, reference_rows(seconds(ref_stamps)))
    (rec,) = read_recordings(tmp_path)
    written = reference_rows(seconds(ref_stamps))
    assert rec.notes["imu_dropped_before"] == 10 and rec.notes["imu_dropped_after"] == 7
    assert np.array_equal(rec.time, (ref_stamps - ref_stamps[0]).astype(float) * 1e-9)
    assert np.array_equal(rec.inputs, imu_rows(seconds(ref_stamps)))
    np.testing.assert_allclose(rec.truth[:, 0:4], written[:, 3:7], rtol=0, atol=ROUND_OFF)
    np.testing.assert_allclose(rec.truth[:, 4:7], written[:, 0:3], rtol=0, atol=ROUND_OFF)
    np.testing.assert_allclose(rec.truth[:, 7:16], written[:, 7:16], rtol=0, atol=ROUND_OFF)
    assert rec.measurements.shape == (ref_stamps.size, 0)


def test_the_reference_between_its_samples_is_exact_for_a_constant_rate_and_velocity(tmp_path):
    """Reference at 50 Hz, IMU at 200 Hz (fractions 0, ¼, ½, ¾): slerp is exact on a rotation at a
    constant body rate and linear interpolation on a constant velocity; a component-wise
    (normalised linear) quaternion interpolation misses by O(Δθ³) at the quarter points."""
    rate, velocity = np.array([0.9, -0.4, 1.7]), np.array([0.5, -1.0, 0.2])
    q0 = quat.normalize(np.array([0.8, 0.1, -0.3, 0.5]))

    def rows(t):
        q = quat.multiply(q0, quat.exp(t[:, None] * rate))
        p = np.array([1.0, 2.0, 3.0]) + t[:, None] * velocity
        return np.concatenate([p, q, np.broadcast_to(velocity, p.shape), np.zeros((t.size, 6))], axis=-1)

    imu_stamps = stamps(PERIOD_NS, 41)
    ref_stamps = stamps(4 * PERIOD_NS, 11)
    write_euroc(tmp_path, imu_stamps, np.zeros((41, 6)), ref_stamps, rows(seconds(ref_stamps)))
    rec = read_euroc(tmp_path)
    expected = rows(seconds(imu_stamps))
    sign = np.sign(np.sum(rec.truth[:, 0:4] * expected[:, 3:7], axis=-1, keepdims=True))
    np.testing.assert_allclose(sign * rec.truth[:, 0:4], expected[:, 3:7], rtol=0, atol=ROUND_OFF)
    np.testing.assert_allclose(rec.truth[:, 4:7], expected[:, 0:3], rtol=0, atol=ROUND_OFF)


def _final_position_error(folder, period: float) -> float:
    """Position error after the INS mechanisation flies the folder's IMU from the first reference
    state without any update."""
    data = build_ins_data(_settings(folder, period=period))
    x = data.truth[:, 0]
    for k in range(1, data.time.size):
        x = data.model.f(x[:, None], data.inputs[:, k - 1])[:, 0]
    return float(np.linalg.norm(x[0, 4:7] - data.truth[0, -1, 4:7]))


@pytest.mark.slow
def test_the_ins_flies_the_reference_with_the_readers_imu(tmp_path):
    """The frames agree (z up, gravity along −z, quaternions scalar first body → world, biases as
    measured − true): the strapdown error of the reader's IMU against the reader's reference is the
    discretisation error of a second-order method, so halving the step divides it by about four. A
    frame, sign or ordering error leaves an error that does not shrink with the step."""
    coarse = _final_position_error(write_flight(tmp_path / "coarse", 2 * PERIOD_NS, 3.0), 0.01)
    fine = _final_position_error(write_flight(tmp_path / "fine", PERIOD_NS, 3.0), 0.005)
    assert fine < coarse / 3.0, (coarse, fine)


def test_a_recording_is_cut_to_duration_and_starts_at_its_first_sample(tmp_path):
    folder = write_flight(tmp_path, PERIOD_NS, 1.0)
    data = build_ins_data(_settings(folder, duration=0.5))
    assert data.time.size == 101 and data.time[0] == 0.0
    written = reference_rows(seconds(stamps(PERIOD_NS, 101)))
    np.testing.assert_allclose(data.truth[0, :, 4:7], written[:, 0:3], rtol=0, atol=ROUND_OFF)
    assert data.labels["recording"] == str(folder)


def test_the_attitude_model_reads_the_folder_and_predicts_its_accelerometer(tmp_path):
    """``model=attitude`` on the same folder: the gyro is the input, the accelerometer the
    measurement, the reference's attitude and biases the truth; its known earth-frame acceleration
    is the reference velocity's central difference, within the Taylor bound ``h²/6 max|v‴|`` of the
    analytic one inside the record, so the model's accelerometer prediction at the true state
    matches the recorded samples to that bound (a frame or gravity-sign error would miss by 2g)."""
    folder = write_flight(tmp_path, PERIOD_NS, 1.0)
    settings = compose_settings(
        ["model=attitude", "runs=1", f"model.recording={folder}", "sample_period=0.005", "duration=20"]
    )
    data = build_attitude_data(settings)
    t = seconds(stamps(PERIOD_NS, 201))
    written, imu = reference_rows(t), imu_rows(t)
    np.testing.assert_allclose(data.truth[0, :, 0:4], written[:, 3:7], rtol=0, atol=ROUND_OFF)
    np.testing.assert_allclose(data.truth[0, :, 4:10], written[:, 10:16], rtol=0, atol=ROUND_OFF)
    assert np.array_equal(data.measurements[0], imu[:, 3:6])
    bound = 0.005**2 / 6.0 * 16.0 * 0.8**4  # h²/6 max|v‴|: the y axis, sin(2ωt), has v‴ up to (2ω)⁴
    inside = slice(1, 200)
    assert np.max(np.abs(data.inputs[0, inside, 3:6] - motion(t)["a"][inside])) < bound
    predicted = np.stack([data.model.h(data.truth[:, k : k + 1], data.inputs[:, k])[0, 0] for k in range(1, 200)])
    assert np.max(np.abs(predicted - imu[inside, 3:6])) < bound
    assert set(data.sensors) == {"mag"}


def _drop_column(header: str, name: str) -> str:
    return ",".join(cell for cell in header.split(",") if not cell.strip().lstrip("#").startswith(name))


@pytest.mark.parametrize(
    ("breakage", "said"),
    [("no folder", "no_such"), ("no reference file", "state_groundtruth_estimate0/data.csv is missing"),
     ("no a_RS_S_y column", "a_RS_S_y"), ("no q_RS_w column", "q_RS_w")],
)  # fmt: skip
@pytest.mark.slow
def test_a_bad_folder_is_refused_in_one_line_naming_the_key(tmp_path, breakage, said):
    s = stamps(PERIOD_NS, 5)
    imu_header = _drop_column(IMU_HEADER, "a_RS_S_y") if "a_RS_S_y" in breakage else IMU_HEADER
    ref_header = _drop_column(REFERENCE_HEADER, "q_RS_w") if "q_RS_w" in breakage else REFERENCE_HEADER
    folder = write_euroc(tmp_path / "f", s, imu_rows(seconds(s)), s, reference_rows(seconds(s)), imu_header, ref_header)
    if breakage == "no reference file":
        (folder / "mav0" / "state_groundtruth_estimate0" / "data.csv").unlink()
    with pytest.raises(ConfigError) as err:
        validate_ins(_settings(tmp_path / "no_such" if breakage == "no folder" else folder))
    assert str(err.value).startswith("model.recording=") and said in str(err.value)
    assert "\n" not in str(err.value)


def test_a_dropped_imu_sample_is_refused_naming_sample_period(tmp_path):
    s = np.delete(stamps(PERIOD_NS, 40), 20)
    write_euroc(tmp_path, s, imu_rows(seconds(s)), s, reference_rows(seconds(s)))
    with pytest.raises(ConfigError, match=r"^sample_period=0\.005 "):
        build_ins_data(_settings(tmp_path))


def _quadest(args, cwd):
    env = {**os.environ, "HYDRA_FULL_ERROR": "0"}
    return subprocess.run(
        [sys.executable, "-m", "quadest.app.cli", *args], cwd=cwd, capture_output=True, text=True, timeout=300, env=env
    )


@pytest.mark.integration
@pytest.mark.slow
def test_quadest_refuses_a_folder_without_the_imu_file_with_exit_2(tmp_path):
    (tmp_path / "empty" / "mav0").mkdir(parents=True)
    proc = _quadest(["model=ins", f"model.recording={tmp_path / 'empty'}", f"hydra.run.dir={tmp_path / 'o'}"], tmp_path)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "model.recording=" in lines[0] and "imu0/data.csv is missing" in lines[0]
    assert not (tmp_path / "o" / "metrics.csv").exists()


@pytest.mark.parametrize(
    ("model", "extra", "truth_columns", "written_columns"),
    [("ins", ["model.aiding=[gps]"], slice(4, 7), slice(0, 3)), ("attitude", [], slice(0, 4), slice(3, 7))],
)
@pytest.mark.integration
@pytest.mark.slow
def test_quadest_runs_on_a_euroc_folder(tmp_path, model, extra, truth_columns, written_columns):
    """The whole job, with the written reference as the truth of ``timeseries.npz`` (position for
    the INS, the quaternion for the attitude filter) and finite errors for every state."""
    folder = write_flight(tmp_path / "flight", PERIOD_NS, 2.0)
    out = tmp_path / "o"
    proc = _quadest(
        [f"model={model}", f"model.recording={folder}", *extra, "sample_period=0.005", "duration=2.0", "runs=1",
         "estimator=[mekf]", "output.figures=false", "progress=false", "cache.enabled=false", f"hydra.run.dir={out}"],
        tmp_path,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    table = pd.read_csv(out / "metrics.csv")
    rows = table[(table["estimator"] == "mekf") & (table["quantity"] == "filter")]
    assert len(rows) > 0 and np.isfinite(rows["rmse"]).all()
    truth = np.load(out / "timeseries.npz")["truth"][0]
    written = reference_rows(seconds(stamps(PERIOD_NS, 401)))
    np.testing.assert_allclose(truth[:, truth_columns], written[:, written_columns], rtol=0, atol=ROUND_OFF)
    if model == "ins":  # the trajectory errors of the job (docs/metrics.md) read its series
        errors = write_trajectory_errors(out, [0.5])
        assert list(errors["measure"]) == ["ate_se3", "ate_4dof", "rpe"] and np.isfinite(errors["position_m"]).all()


def test_the_data_is_keyed_by_the_folders_csv_bytes(tmp_path):
    """A folder rewritten in place is other data (docs/cache.md): the data key holds the two CSVs' digest."""
    folder = write_flight(tmp_path, PERIOD_NS, 0.1)
    cfg = compose_config(["model=ins", f"model.recording={folder}", "sample_period=0.005"])
    first = data_key(cfg)
    imu = folder / "mav0" / "imu0" / "data.csv"
    original = imu.read_text()
    imu.write_text(original.replace("0.", "1.", 1))
    assert data_key(cfg) != first
    imu.write_text(original)
    assert data_key(cfg) == first
