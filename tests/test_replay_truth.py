"""The replay's errors against a log's ground truth and the magnetic declination (docs/replay.md).

Each test writes its own ULog with pyulog's writer (``ULog.write_ulog``): the first 12 s of the
shipped log's ``sensor_combined`` and ``vehicle_attitude``, with the parameters of an EKF2 log
(``SYS_MC_EST_GROUP = 2``) and, where a test needs one, a ``vehicle_attitude_groundtruth`` made
from PX4's own estimate:

- truth = PX4's estimate: PX4's errors are zero to double-precision round-off (the same numbers go
  through the same interpolation; the error angle of ``q* ⊗ q`` is 0 up to the round-off of the
  quaternion product, ~1e-16 rad);
- truth = PX4's estimate turned by a yaw δ about NED's down axis, ``q_z(δ) ⊗ q``: PX4's yaw error
  is −δ at every step (ZYX Euler angles: ``q_z(δ) ⊗ q_z(ψ) q_y(θ) q_x(φ)`` has yaw ψ + δ and the
  same roll and pitch) and its attitude error angle is |δ|, so both RMS values are |δ|;
- ``EKF2_MAG_DECL = 3.2``: the same sensors, so the same filter estimates before the declination,
  and every filter's yaw 3.2° east of the one without it (roll and pitch unchanged).

Tolerances: the log stores quaternions and parameters as float32 (relative rounding 6e-8): a
quaternion's four components rounded move its attitude by at most ~2·√4·6e-8 rad = 1.4e-5°, the
declination 3.2 is stored as 3.2000000477; 5e-5° covers the first, the float32 value is used for
the second (whose remaining round-off is that of double-precision products, below 1e-9°).
"""

from __future__ import annotations

import copy
import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest
from pyulog import ULog

from helpers import compose_config
from quadest.app.job import run_job
from quadest.numerics import quaternion as quat
from quadest.replay.data import shipped_log
from quadest.replay.declination import EKF2, Q_ESTIMATOR, declination_parameter, log_declination, to_true_north

SECONDS = 12.0
YAW_OFFSET = 7.5  # degrees: the truth's constant yaw offset from PX4's estimate
DECLINATION = 3.2
FLOAT32_ATTITUDE = 5e-5  # degrees (module docstring)
ROUND_OFF = 1e-9  # degrees
STATES = ["roll", "pitch", "yaw", "attitude"]
ESTIMATORS = ["mekf", "madgwick"]


def write_log(path: Path, truth_yaw: float | None, parameters: dict[str, float]) -> Path:
    """The shipped log's first :data:`SECONDS` s of IMU and attitude, its parameters updated by
    ``parameters``, and (unless ``truth_yaw`` is None) a ``vehicle_attitude_groundtruth`` equal to
    ``vehicle_attitude`` turned by ``truth_yaw`` degrees about NED's down axis."""
    ulog = ULog(str(shipped_log()), ["sensor_combined", "vehicle_attitude"])
    start = min(int(d.data["timestamp"][0]) for d in ulog.data_list)
    for d in ulog.data_list:
        keep = d.data["timestamp"] < start + SECONDS * 1e6
        d.data = {k: v[keep] for k, v in d.data.items()}
    ulog.initial_parameters.update(parameters)
    if truth_yaw is not None:
        att = next(d for d in ulog.data_list if d.name == "vehicle_attitude")
        truth = copy.copy(att)
        truth.name, truth.msg_id = "vehicle_attitude_groundtruth", max(d.msg_id for d in ulog.data_list) + 1
        q = np.column_stack([att.data[f"q[{i}]"] for i in range(4)]).astype(float)
        turned = quat.multiply(quat.from_euler(np.radians([0.0, 0.0, truth_yaw])), q)
        truth.data = {**att.data, **{f"q[{i}]": turned[:, i].astype(np.float32) for i in range(4)}}
        ulog.data_list.append(truth)
        fmt = copy.copy(ulog.message_formats["vehicle_attitude"])
        fmt.name = truth.name
        ulog.message_formats[truth.name] = fmt
    ulog.write_ulog(str(path))
    return path


def replay(log: Path, out: Path) -> dict:
    overrides = ["experiment=px4_replay", f"source.path={log}", f"estimator=[{','.join(ESTIMATORS)}]",
                 "progress=false", "workers=1", "output.figures=false", "cache.enabled=false"]  # fmt: skip
    return run_job(compose_config(overrides), out, overrides)


EKF2_LOG = {"SYS_MC_EST_GROUP": 2}


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> dict[str, tuple[Path, dict]]:
    """Three replays: truth = PX4 (no declination), truth = PX4 turned by 7.5° with a declination of
    3.2°, and no truth."""
    root = tmp_path_factory.mktemp("truth")
    logs = {
        "same": write_log(root / "same.ulg", 0.0, EKF2_LOG),
        "offset": write_log(root / "offset.ulg", YAW_OFFSET, {**EKF2_LOG, EKF2: DECLINATION}),
        "none": write_log(root / "none.ulg", None, EKF2_LOG),
    }
    return {name: (root / name, replay(log, root / name)) for name, log in logs.items()}


def truth_table(out: Path) -> pd.Series:
    table = pd.read_csv(out / "truth_errors.csv")
    assert list(table.columns) == ["estimator", "state", "unit", "rms"]
    assert set(table["unit"]) == {"deg"}
    return table.set_index(["estimator", "state"])["rms"]


@pytest.mark.slow
def test_the_written_log_holds_what_the_tests_rely_on(runs, tmp_path):
    """The writer's round trip: the truth topic and the parameter are read back as written."""
    path = write_log(tmp_path / "offset.ulg", YAW_OFFSET, {**EKF2_LOG, EKF2: DECLINATION})
    ulog = ULog(str(path))
    assert ulog.initial_parameters[EKF2] == pytest.approx(DECLINATION, rel=1e-7)
    names = {d.name for d in ulog.data_list}
    assert {"vehicle_attitude", "vehicle_attitude_groundtruth"} <= names


@pytest.mark.slow
def test_truth_equal_to_px4s_estimate_gives_px4_zero_error_in_every_state(runs):
    out, summary = runs["same"]
    rms = truth_table(out)
    assert set(rms.index.get_level_values("estimator")) == {*ESTIMATORS, "px4"}
    for state in STATES:
        assert rms["px4", state] == pytest.approx(0.0, abs=ROUND_OFF), state
    # every filter's error against this truth is its difference to PX4 (rmse_summary.csv)
    to_px4 = pd.read_csv(out / "rmse_summary.csv").set_index(["estimator", "state"])["rmse_mean"]
    for name in ESTIMATORS:
        for state in STATES:
            assert rms[name, state] == pytest.approx(to_px4[name, state], rel=1e-12, abs=ROUND_OFF), (name, state)
    assert summary["truth_errors"]["px4"]["yaw"] == pytest.approx(0.0, abs=ROUND_OFF)
    assert "errors against it in truth_errors.csv" in summary["_caption"]


@pytest.mark.parametrize("doc", ["outputs.md", "replay.md"])
@pytest.mark.slow
def test_the_docs_list_the_columns_written(runs, doc):
    """The column table of truth_errors.csv in the docs names exactly the columns written."""
    text = (Path(__file__).resolve().parents[1] / "docs" / doc).read_text()
    part = text[text.index("`truth_errors.csv`") :]
    table = part[part.index("| column") :].split("\n\n")[0].split("\n-")[0]
    rows = [line.strip() for line in table.splitlines()[2:]]
    documented = [line.split("|")[1].strip().strip("`") for line in rows if line.startswith("|")]
    assert documented == list(pd.read_csv(runs["same"][0] / "truth_errors.csv").columns)


@pytest.mark.slow
def test_a_constant_yaw_offset_of_the_truth_is_px4s_yaw_and_attitude_error(runs):
    out, summary = runs["offset"]
    rms = truth_table(out)
    assert rms["px4", "roll"] == pytest.approx(0.0, abs=FLOAT32_ATTITUDE)
    assert rms["px4", "pitch"] == pytest.approx(0.0, abs=FLOAT32_ATTITUDE)
    assert rms["px4", "yaw"] == pytest.approx(YAW_OFFSET, abs=FLOAT32_ATTITUDE)
    assert rms["px4", "attitude"] == pytest.approx(YAW_OFFSET, abs=FLOAT32_ATTITUDE)
    # a filter's yaw error against the truth is its yaw difference to PX4 minus the offset, from the saved angles
    series = np.load(out / "timeseries.npz")
    window = series["time"] >= series["time"][0] + summary["compared_from"]
    for name in ESTIMATORS:
        diff = series[f"{name}/angles_deg"][:, 2] - series["reference_angles_deg"][:, 2] - YAW_OFFSET
        expected = np.sqrt(np.mean(((diff[window] + 180.0) % 360.0 - 180.0) ** 2))
        assert rms[name, "yaw"] == pytest.approx(expected, abs=FLOAT32_ATTITUDE), name


@pytest.mark.slow
def test_the_logs_declination_turns_every_filters_yaw_by_it(runs):
    """The same sensors with EKF2_MAG_DECL = 3.2: every filter's yaw 3.2° larger at every step,
    roll and pitch the same, and the report says where the value came from."""
    (same, same_summary), (offset, summary) = runs["same"], runs["offset"]
    stored = float(np.float32(DECLINATION))
    without, with_ = np.load(same / "timeseries.npz"), np.load(offset / "timeseries.npz")
    for name in ESTIMATORS:
        turn = with_[f"{name}/angles_deg"] - without[f"{name}/angles_deg"]
        np.testing.assert_allclose((turn[:, 2] + 180.0) % 360.0 - 180.0, stored, rtol=0, atol=ROUND_OFF)
        np.testing.assert_allclose(turn[:, :2], 0.0, rtol=0, atol=ROUND_OFF)
    assert summary["declination"]["deg"] == pytest.approx(stored, abs=1e-12)
    assert summary["declination"]["source"] == EKF2 and EKF2 in summary["_caption"]
    assert same_summary["declination"] == {"deg": 0.0, "source": "none", "note": same_summary["declination"]["note"]}
    assert f"no {EKF2} parameter" in same_summary["_caption"]


@pytest.mark.slow
def test_a_log_without_ground_truth_writes_no_truth_errors_and_says_so(runs):
    out, summary = runs["none"]
    assert not (out / "truth_errors.csv").exists()
    assert summary["truth_errors"] is None
    assert "The log has no ground truth" in summary["_caption"]
    assert "The log has no ground truth" in (out / "rmse_table.md").read_text()
    assert (out / "rmse_summary.csv").is_file()  # the differences to PX4 as before
    assert json.loads((out / "summary.json").read_text())["ground_truth"].startswith("The log has no ground truth")


# --- the declination's source, without a job ---


@pytest.mark.parametrize(
    ("parameters", "name"),
    [({"SYS_MC_EST_GROUP": 2}, EKF2), ({"SYS_MC_EST_GROUP": 1}, Q_ESTIMATOR), ({"SYS_MC_EST_GROUP": 3}, Q_ESTIMATOR),
     ({"EKF2_EN": 0, "ATT_EN": 1}, Q_ESTIMATOR), ({"EKF2_EN": 1}, EKF2), ({}, EKF2)],
)  # fmt: skip
def test_the_declination_is_the_parameter_of_the_estimator_that_ran(parameters, name):
    assert declination_parameter(parameters) == name


def test_the_last_logged_change_of_the_declination_counts():
    parameters = {"SYS_MC_EST_GROUP": 2, EKF2: 1.0}
    got = log_declination(parameters, ((10.0, EKF2, 2.5), (20.0, "OTHER", 9.0), (30.0, EKF2, 3.2)))
    assert got.deg == 3.2 and got.source == EKF2 and "last change" in got.note
    assert log_declination(parameters, ()).deg == 1.0


def test_the_shipped_log_is_referenced_by_attitude_estimator_qs_declination_zero():
    from quadest.replay.ulog import read_flight_log

    log = read_flight_log(shipped_log())
    got = log_declination(log.parameters, log.parameter_changes)
    assert (got.deg, got.source) == (0.0, Q_ESTIMATOR) and log.truth_q is None and not log.position_truth


@pytest.mark.parametrize(
    ("ground_truth", "position_truth", "line"),
    [(np.zeros((2, 4)), False, "Ground truth: vehicle_attitude_groundtruth"),
     (None, True, "has vehicle_local_position_groundtruth but no vehicle_attitude_groundtruth"),
     (None, False, "The log has no ground truth")],
)  # fmt: skip
def test_the_caption_names_what_truth_the_log_has(ground_truth, position_truth, line):
    from quadest.app.replay_job import truth_line

    assert line in truth_line(SimpleNamespace(ground_truth=ground_truth, position_truth=position_truth))


def test_turning_to_true_north_adds_the_declination_to_yaw_alone():
    angles = np.radians([[10.0, -20.0, 170.0], [-5.0, 3.0, -30.0]])
    states = np.concatenate([quat.from_euler(angles), np.ones((2, 6))], axis=1)
    turned = to_true_north(states, 15.0)
    expected = np.degrees(angles) + [0.0, 0.0, 15.0]
    expected[:, 2] = (expected[:, 2] + 180.0) % 360.0 - 180.0
    np.testing.assert_allclose(np.degrees(quat.to_euler(turned[:, :4])), expected, atol=1e-12)
    np.testing.assert_array_equal(turned[:, 4:], states[:, 4:])
