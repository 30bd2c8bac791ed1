"""The magnetic declination of a flight log, and our filters' attitude turned from magnetic to true north.

Our filters reference yaw to *magnetic* north: the replay's earth field is the log's own levelled
magnetometer, north component along x (:func:`quadest.replay.data.earth_field`), and the first yaw
comes from the magnetometer (:func:`quadest.replay.data.initial_state`). PX4 references its yaw to
*true* north: its estimators turn the magnetometer's heading by the declination ``D`` (degrees,
positive east), which they keep in a parameter, ``EKF2_MAG_DECL`` for EKF2 and ``ATT_MAG_DECL`` for
``attitude_estimator_q`` (PX4 parameter reference), set from the World Magnetic Model when the
vehicle has a GPS fix (``EKF2_DECL_TYPE``, ``ATT_MAG_DECL_A``) and saved back into the parameter.

A heading ``ψ_m`` from magnetic north is ``ψ = ψ_m + D`` from true north: the magnetic frame's x
axis is the true frame's ``[cos D, sin D, 0]``, so the body→true-NED quaternion is
``q = q_z(D) ⊗ q_m`` (roll and pitch unchanged). The replay applies this to every filter's
estimate before comparing it with PX4 or with the truth; nothing else in the replay uses the
declination, so it is applied once.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from quadest.numerics import quaternion as quat

EKF2 = "EKF2_MAG_DECL"
Q_ESTIMATOR = "ATT_MAG_DECL"
EKF2_GROUP = 2
"""``SYS_MC_EST_GROUP`` of EKF2 (PX4 ≤ 1.13; 0, 1 and 3 run ``attitude_estimator_q``)."""


@dataclass(frozen=True)
class Declination:
    """The declination applied to our filters' yaw.

    Attributes:
        deg: degrees, positive east (0 when the log has none).
        source: the parameter it came from, or ``"none"``.
        note: one line for the caption: the value, where it came from and which logged value.
    """

    deg: float
    source: str
    note: str


def declination_parameter(parameters: dict[str, float]) -> str:
    """The declination parameter of the estimator that published ``vehicle_attitude``: EKF2's unless
    the log says ``attitude_estimator_q`` ran (``SYS_MC_EST_GROUP`` ≠ 2 up to PX4 1.13; from 1.14,
    ``EKF2_EN`` = 0 with ``ATT_EN`` = 1)."""
    if "SYS_MC_EST_GROUP" in parameters:
        return EKF2 if int(parameters["SYS_MC_EST_GROUP"]) == EKF2_GROUP else Q_ESTIMATOR
    if parameters.get("EKF2_EN", 1) == 0 and parameters.get("ATT_EN", 0) == 1:
        return Q_ESTIMATOR
    return EKF2


def log_declination(parameters: dict[str, float], changes: tuple[tuple[float, str, float], ...]) -> Declination:
    """The declination of a log from its parameters at the start and the changes logged in flight.

    The last logged value counts: PX4 saves the World Magnetic Model's declination into the
    parameter when it has a GPS fix, so a change during the log is the value the estimator used at
    this site, and the value at the start may be the previous flight's. A log without the
    parameter gives 0 (yaw compared as magnetic), said in the note.
    """
    name = declination_parameter(parameters)
    changed = [(t, value) for t, key, value in changes if key == name]
    if changed:
        t, value = changed[-1]
        start = f"; {parameters[name]:g}° at the start" if name in parameters else ""
        return Declination(float(value), name, f"{value:g}° from the {name} parameter, its last change in the "
                           f"log (t = {t:.1f} s of the autopilot's clock{start})")  # fmt: skip
    if name in parameters:
        value = float(parameters[name])
        return Declination(value, name, f"{value:g}° from the {name} parameter (its value at the log's start)")
    return Declination(0.0, "none", f"0°: the log has no {name} parameter, so yaw is compared as magnetic")


def to_true_north(states: np.ndarray, declination_deg: float) -> np.ndarray:
    """States (..., ≥ 4) whose first four entries are the body→magnetic-NED quaternion, with that
    quaternion turned to true north, ``q_z(D) ⊗ q`` (module docstring); the other entries as they are."""
    turn = quat.from_euler(np.array([0.0, 0.0, np.radians(declination_deg)]))
    out = np.array(states, dtype=float, copy=True)
    out[..., :4] = quat.multiply(turn, out[..., :4])
    return out
