"""Read the sensor data and PX4's own attitude estimate out of a PX4 ULog file.

Two message layouts occur in real logs (PX4 uORB message definitions, ``msg/*.msg``):

- **older** (PX4 ≤ 1.6, the shipped ``sample.ulg``): ``sensor_combined`` carries gyro,
  accelerometer *and* magnetometer (``magnetometer_ga[3]``, its time as
  ``magnetometer_timestamp_relative`` to the gyro's ``timestamp``);
- **current**: ``sensor_combined`` carries gyro and accelerometer only, the calibrated magnetometer
  in the body frame is ``vehicle_magnetometer`` (``magnetometer_ga[3]``), or the per-device
  ``sensor_mag`` (``x, y, z``) in logs without it; the GPS is ``vehicle_gps_position`` or
  ``sensor_gps``.

A simulation (SITL) log also records the simulator's truth: ``vehicle_attitude_groundtruth``
(``q[0..3]`` as in ``vehicle_attitude``) and ``vehicle_local_position_groundtruth``. The log's
parameters (their values at the start, ``initial_parameters``, and the changes logged during the
flight, ``changed_parameters``) come along for the magnetic declination
(:mod:`quadest.replay.declination`).

Units and frames as PX4 logs them: gyro rad/s and accelerometer m/s² (specific force) in the body
frame FRD, magnetometer gauss in FRD, attitude ``vehicle_attitude.q[0..3]`` (w, x, y, z) rotating
body FRD to earth NED, GPS velocity m/s in NED. Timestamps are integers in µs of the autopilot's
boot clock; each sample is timed by ``timestamp_sample`` where the topic has it, otherwise by
``timestamp`` (plus the relative offset for the accelerometer and old-layout magnetometer).

The reader works on anything shaped like ``pyulog.ULog`` (``data_list`` of items with ``name``,
``multi_id`` and a ``data`` dict of arrays), so tests can feed a small fake log.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from quadest.errors import ConfigError

#: ``*_timestamp_relative`` value meaning "no sample" (``sensor_combined.RELATIVE_TIMESTAMP_INVALID``).
RELATIVE_TIMESTAMP_INVALID = 2147483647

_MAG_TOPICS = ("vehicle_magnetometer", "sensor_mag")
_GPS_TOPICS = ("vehicle_gps_position", "sensor_gps")
ATTITUDE_TRUTH = "vehicle_attitude_groundtruth"
POSITION_TRUTH = "vehicle_local_position_groundtruth"


class MissingTopicError(ConfigError):
    """A topic (or field) the replay needs is not in the log; one line naming it and the file."""

    def __init__(self, path: str, topic: str, detail: str = "") -> None:
        ValueError.__init__(self, f"{path}: the log has no {topic}{detail}; the PX4 replay needs it (docs/replay.md)")
        self.key, self.value, self.allowed = "source.path", path, f"a log with {topic}"


@dataclass(frozen=True)
class FlightLog:
    """The samples a replay uses, times in seconds of the autopilot's clock.

    Attributes:
        path: where the log was read from (for messages).
        layout: ``"older"`` (magnetometer in ``sensor_combined``) or ``"current"``.
        imu_time: (N,) gyro sample times; ``gyro`` (N, 3) rad/s, FRD.
        accel_time, accel: (A,) and (A, 3) specific force, m/s², FRD (``timestamp`` plus
            ``accelerometer_timestamp_relative``: 0 in the older layout, a few µs in current logs);
            rows whose offset is ``RELATIVE_TIMESTAMP_INVALID`` hold no accelerometer sample and
            are left out.
        mag_time, mag: (M,) and (M, 3) gauss, FRD; each distinct sample once.
        reference_time, reference_q: PX4's onboard attitude estimate ``vehicle_attitude``,
            (R,) and (R, 4) scalar-first unit quaternions, body FRD → earth NED.
        gps_time, gps_velocity: (G,) and (G, 3) m/s NED, or ``None`` when the log has no GPS topic.
        truth_time, truth_q: the simulator's attitude ``vehicle_attitude_groundtruth``, (S,) and
            (S, 4) like ``reference_q``, or ``None`` when the log has none (a real flight).
        position_truth: whether the log holds ``vehicle_local_position_groundtruth``.
        parameters: name → value of the log's parameters at its start.
        parameter_changes: ``(time [s], name, value)`` of each parameter change logged in flight.
    """

    path: str
    layout: str
    imu_time: np.ndarray
    gyro: np.ndarray
    accel_time: np.ndarray
    accel: np.ndarray
    mag_time: np.ndarray
    mag: np.ndarray
    reference_time: np.ndarray
    reference_q: np.ndarray
    gps_time: np.ndarray | None = None
    gps_velocity: np.ndarray | None = None
    truth_time: np.ndarray | None = None
    truth_q: np.ndarray | None = None
    position_truth: bool = False
    parameters: dict[str, float] = field(default_factory=dict)
    parameter_changes: tuple[tuple[float, str, float], ...] = ()


def read_flight_log(path: str | Path) -> FlightLog:
    """Read ``path`` with pyulog (only the topics the replay uses) into a :class:`FlightLog`."""
    from pyulog import ULog

    path = str(path)
    if not Path(path).is_file():
        raise ConfigError("source.path", path, "an existing PX4 ULog file (.ulg)")
    topics = ["sensor_combined", "vehicle_attitude", *_MAG_TOPICS, *_GPS_TOPICS, ATTITUDE_TRUTH, POSITION_TRUTH]
    try:
        ulog = ULog(path, topics)
    except Exception as exc:  # pyulog raises bare exceptions on a file that is not a ULog
        raise ConfigError("source.path", path, f"a readable PX4 ULog file ({type(exc).__name__}: {exc})") from None
    return flight_log_from(ulog, path)


def flight_log_from(ulog, path: str = "<log>") -> FlightLog:
    """A :class:`FlightLog` from a parsed ULog (or an object shaped like one), either layout.

    Raises:
        MissingTopicError: ``sensor_combined`` or ``vehicle_attitude`` is missing, or the log has
            no magnetometer in any of the places listed in the module docstring.
    """
    topics = _first_instances(ulog)
    sc = _topic(topics, "sensor_combined", path)
    imu_time = _seconds(sc["timestamp"])
    gyro = _vector(sc, "gyro_rad", path, "sensor_combined")
    accel_relative = sc.get("accelerometer_timestamp_relative", np.zeros_like(sc["timestamp"]))
    accel_valid = accel_relative != RELATIVE_TIMESTAMP_INVALID  # a row without an accelerometer sample
    accel = _vector(sc, "accelerometer_m_s2", path, "sensor_combined")[accel_valid]
    accel_time = _seconds((sc["timestamp"] + accel_relative)[accel_valid])
    if "magnetometer_ga[0]" in sc:
        layout = "older"
        valid = sc["magnetometer_timestamp_relative"] != RELATIVE_TIMESTAMP_INVALID
        stamps = (sc["timestamp"] + sc["magnetometer_timestamp_relative"])[valid]
        mag_all = _vector(sc, "magnetometer_ga", path, "sensor_combined")[valid]
        first = np.concatenate([[True], np.diff(stamps) != 0])  # the latest sample is repeated until a new one
        mag_time, mag = _seconds(stamps[first]), mag_all[first]
    else:
        layout = "current"
        name = next((t for t in _MAG_TOPICS if t in topics), None)
        if name is None:
            raise MissingTopicError(path, " or ".join(_MAG_TOPICS), " (nor a magnetometer in sensor_combined)")
        msg = topics[name]
        mag_time = _seconds(_sample_stamps(msg))
        mag = _vector(msg, "magnetometer_ga", path, name) if name == "vehicle_magnetometer" else _xyz(msg, path, name)
    att = _topic(topics, "vehicle_attitude", path)
    reference_q = _vector(att, "q", path, "vehicle_attitude", 4)
    gps = next((t for t in _GPS_TOPICS if t in topics), None)
    gps_time = gps_velocity = None
    if gps is not None:
        gps_time = _seconds(_sample_stamps(topics[gps]))
        gps_velocity = np.column_stack([topics[gps][f"vel_{a}_m_s"] for a in "ned"]).astype(float)
    reference_time = _seconds(_sample_stamps(att))
    truth_time = truth_q = None
    if ATTITUDE_TRUTH in topics and len(topics[ATTITUDE_TRUTH]["timestamp"]):
        truth_time = _seconds(_sample_stamps(topics[ATTITUDE_TRUTH]))
        truth_q = _unit(_vector(topics[ATTITUDE_TRUTH], "q", path, ATTITUDE_TRUTH, 4))
    changes = tuple(
        (float(t) * 1e-6, str(name), float(value)) for t, name, value in getattr(ulog, "changed_parameters", ())
    )
    return FlightLog(
        path=path, layout=layout, imu_time=imu_time, gyro=gyro, accel_time=accel_time, accel=accel,
        mag_time=mag_time, mag=mag, reference_time=reference_time, reference_q=_unit(reference_q),
        gps_time=gps_time, gps_velocity=gps_velocity, truth_time=truth_time, truth_q=truth_q,
        position_truth=POSITION_TRUTH in topics,
        parameters={str(k): float(v) for k, v in getattr(ulog, "initial_parameters", {}).items()},
        parameter_changes=changes,
    )  # fmt: skip


def _unit(q: np.ndarray) -> np.ndarray:
    return q / np.linalg.norm(q, axis=1)[:, None]


def _first_instances(ulog) -> dict[str, dict[str, np.ndarray]]:
    """Topic name → field arrays of its first instance (``multi_id`` 0, else the lowest)."""
    topics: dict[str, tuple[int, dict]] = {}
    for d in ulog.data_list:
        if d.name not in topics or d.multi_id < topics[d.name][0]:
            topics[d.name] = (d.multi_id, d.data)
    return {name: data for name, (_, data) in topics.items()}


def _topic(topics: dict, name: str, path: str) -> dict[str, np.ndarray]:
    if name not in topics or len(topics[name]["timestamp"]) == 0:
        raise MissingTopicError(path, name)
    return topics[name]


def _vector(msg: dict, field: str, path: str, topic: str, size: int = 3) -> np.ndarray:
    keys = [f"{field}[{i}]" for i in range(size)]
    if any(k not in msg for k in keys):
        raise MissingTopicError(path, f"{topic}.{field}")
    return np.column_stack([msg[k] for k in keys]).astype(float)


def _xyz(msg: dict, path: str, topic: str) -> np.ndarray:
    if any(a not in msg for a in "xyz"):
        raise MissingTopicError(path, f"{topic}.x/y/z")
    return np.column_stack([msg[a] for a in "xyz"]).astype(float)


def _sample_stamps(msg: dict) -> np.ndarray:
    """When each sample was taken: ``timestamp_sample`` where the topic has it, else ``timestamp``."""
    return msg["timestamp_sample"] if "timestamp_sample" in msg else msg["timestamp"]


def _seconds(stamps_us: np.ndarray) -> np.ndarray:
    return np.asarray(stamps_us, dtype=np.int64) * 1e-6


ULOG_HEADER_BYTES = 16  # magic (7), version (1), timestamp (8)
MESSAGE_HEADER_BYTES = 3  # msg_size (uint16, little endian), msg_type (uint8)


def incomplete_tail(path: str | Path) -> int:
    """Bytes at the end of a ULog file that do not make a whole message: 0 for a file that ends on
    a message boundary, > 0 for one cut while a message was written (a copy or a download that
    stopped, a logger that lost power). Every message after the 16-byte file header starts with its
    size and type (the ULog file format of PX4's documentation, "Message Header"); pyulog reads up
    to the last whole message without a word, so the cut is found by walking the headers."""
    data = Path(path).read_bytes()
    offset = ULOG_HEADER_BYTES
    while offset < len(data):
        end = offset + MESSAGE_HEADER_BYTES + int.from_bytes(data[offset : offset + 2], "little")
        if offset + MESSAGE_HEADER_BYTES > len(data) or end > len(data):
            return len(data) - offset
        offset = end
    return 0
