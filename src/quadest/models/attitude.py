"""``model=attitude``: quaternion attitude with gyro and accelerometer biases (seed 002, corrected;
docs/attitude.md lists the corrections).

State ``x = [q (4, scalar first, body → earth), b_g (3), b_a (3)]`` (n = 10); error state
``δx = [δθ (3, body frame), δb_g, δb_a]`` (n_err = 9) with ``x ⊞ δx = [q ⊗ exp(δθ), b_g + δb_g,
b_a + δb_a]`` (right perturbation, :mod:`quadest.numerics.quaternion`; Solà 2017 §7).

Input ``u = [ω_m (3), a_e (3)]``: the gyro sample (rad/s) and the earth-frame linear acceleration
of the vehicle (m/s²), which the accelerometer model needs. Pass ``a_e = 0`` when it is not known
(a log replay, or ``known_acceleration: false``), and account for the vehicle's acceleration in
``R_acc``.

- transition (Solà eq. 260 with the zero-order hold of the gyro): ``ω = C (ω_m − b_g)``,
  ``q⁺ = q ⊗ exp(ω T)``, ``b_g⁺ = b_g``, ``b_a⁺ = b_a``; ``C`` undoes the gyro's known
  scale-factor/misalignment/asymmetry errors (identity unless calibrated);
- accelerometer (the primary measurement, every step): ``z = A(R(q)ᵀ (a_e − g_e)) + b_a``,
  with ``g_e`` the earth-frame gravity vector and ``A`` the accelerometer's known deterministic
  errors (identity unless calibrated);
- magnetometer (sensor ``"mag"``, at its own rate): ``z = M(R(q)ᵀ m_e)`` with ``m_e`` the earth
  field and ``M`` the known soft/hard-iron errors (:mod:`quadest.sensors.magnetometer`).

Frames: the model takes ``gravity_earth`` and ``mag_earth`` in whatever earth frame the data use,
so one class serves the simulation (ENU-like, z up: ``g_e = [0, 0, −9.81]``) and a PX4 log (NED:
``g_e = [0, 0, +9.81]``, ``m_e`` north/east/down). Construct it directly as::

    AttitudeFilterModel(T, gravity_earth, mag_earth, Q, R_acc, R_mag)            # one run
    AttitudeFilterModel(T, g_e, m_e, Q, R_acc, R_mag, batch_size=B,
                        gyro_errors=..., accel_errors=..., mag_errors=...)    # calibrated, per run

``Q`` is the 9×9 covariance of the error-state process noise per step, ``R_acc`` and ``R_mag``
3×3. Errors left at ``None`` are the nominal error-free triads.

Error-state Jacobians are analytic (derivations in docs/attitude.md; finite differences on the
manifold check them in tests/test_attitude.py):

    F_err = [[Exp(φ)ᵀ, −T J_r(φ) C, 0], [0, I, 0], [0, 0, I]],   φ = ω T
    H_acc = [A' [f_b]×, 0, I],   f_b = R(q)ᵀ (a_e − g_e)
    H_mag = [M' [m_b]×, 0, 0],   m_b = R(q)ᵀ m_e

with ``A'``, ``M'`` the Jacobians of the deterministic sensor errors, ``J_r`` the right Jacobian
of SO(3) (Solà eq. 143) and ``[·]×`` the skew matrix.
"""

from __future__ import annotations

import numpy as np

from quadest.models.base import FilterModel, MeasurementModel
from quadest.numerics import quaternion as quat
from quadest.quadrotor.kinematics import wrap_angle
from quadest.sensors.mimu import TriadErrors

STATE_NAMES = ("qw", "qx", "qy", "qz", "bg_x", "bg_y", "bg_z", "ba_x", "ba_y", "ba_z")
STATE_UNITS = ("-",) * 4 + ("rad/s",) * 3 + ("m/s^2",) * 3
ERROR_NAMES = ("dtheta_x", "dtheta_y", "dtheta_z", "bg_x", "bg_y", "bg_z", "ba_x", "ba_y", "ba_z")
ERROR_UNITS = ("rad",) * 3 + ("rad/s",) * 3 + ("m/s^2",) * 3
ATTITUDE_ERROR_NAMES = ("error_angle", "roll", "pitch", "yaw")
BIAS_PREFIXES = ("bg_", "ba_")


def attitude_errors_deg(estimate: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Attitude errors in degrees (..., 4) of states whose first four components are the
    quaternion (..., ≥ 4): the error angle ``|log(q* ⊗ q̂)|`` (the angle of the rotation from the
    true to the estimated attitude, in [0, 180]) and the roll, pitch and yaw errors, the
    differences of the ZYX Euler angles (estimate − truth) wrapped to (−180, 180]."""
    angle = np.linalg.norm(quat.boxminus(estimate[..., :4], truth[..., :4]), axis=-1, keepdims=True)
    euler = wrap_angle(quat.to_euler(estimate[..., :4]) - quat.to_euler(truth[..., :4]))
    return np.degrees(np.concatenate([angle, euler], axis=-1))


class AttitudeMetrics:
    """What a model whose state starts with the attitude quaternion reports besides its error
    state (mix in before :class:`FilterModel`, as ``model=attitude`` and ``model=ins`` do): the
    attitude errors in degrees of :func:`attitude_errors_deg` as derived errors, its gyro and
    accelerometer biases (error states named ``bg_*``, ``ba_*``, equal to their state names) for
    the convergence time, and the attitude-error and bias-estimate figures."""

    derived_error_names = ATTITUDE_ERROR_NAMES
    derived_error_units = ("deg",) * 4
    extra_figures = ("attitude_errors", "bias_estimates")

    def derived_errors(self, estimate: np.ndarray, truth: np.ndarray) -> np.ndarray:
        return attitude_errors_deg(estimate, truth)

    @property
    def bias_states(self) -> tuple[str, ...]:
        return tuple(name for name in self.error_names if name.startswith(BIAS_PREFIXES))

    @property
    def state_groups(self) -> dict[str, tuple[str, ...]]:
        """The attitude error, then each further quantity (position, velocity, gyro and accelerometer
        bias: the error states sharing a unit) as its own group."""
        names = {"rad": "attitude", "m": "position", "m/s": "velocity", "rad/s": "gyro_bias", "m/s^2": "accel_bias"}
        groups: dict[str, tuple[str, ...]] = {}
        for name, unit in zip(self.error_names, self.error_units, strict=True):
            groups[names[unit]] = (*groups.get(names[unit], ()), name)
        return groups


class AttitudeFilterModel(AttitudeMetrics, FilterModel):
    """Quaternion attitude with gyro and accelerometer biases (see the module docstring).

    Args:
        sample_period: T (s).
        gravity_earth: earth-frame gravity vector (3,), e.g. ``[0, 0, −9.81]`` for z up.
        mag_earth: earth-frame magnetic field (3,), any unit (R_mag in the same unit squared).
        Q: (9, 9) error-state process noise per step.
        R_acc, R_mag: (3, 3) accelerometer and magnetometer noise covariances.
        gyro_errors, accel_errors, mag_errors: the known deterministic errors per run
            (:class:`TriadErrors`, batch of ``batch_size``); their ``bias`` is part of the model
            only for the magnetometer (hard iron): the gyro and accelerometer biases are states.
        batch_size: runs the model is bound to (taken from the errors when given).
    """

    name = "attitude"
    n = 10
    m = 3
    nu = 6
    state_names = STATE_NAMES
    state_units = STATE_UNITS
    measurement_names = ("acc_x", "acc_y", "acc_z")
    supports_augmented = True

    def __init__(
        self,
        sample_period: float,
        gravity_earth,
        mag_earth,
        Q: np.ndarray,
        R_acc: np.ndarray,
        R_mag: np.ndarray,
        gyro_errors: TriadErrors | None = None,
        accel_errors: TriadErrors | None = None,
        mag_errors: TriadErrors | None = None,
        batch_size: int | None = None,
    ) -> None:
        given = [e for e in (gyro_errors, accel_errors, mag_errors) if e is not None]
        self.batch_size = batch_size if batch_size is not None else (given[0].bias.shape[0] if given else 1)
        self.dt = float(sample_period)
        self.gravity_earth = np.asarray(gravity_earth, dtype=float).reshape(3)
        self.mag_earth = np.asarray(mag_earth, dtype=float).reshape(3)
        self.Q = np.asarray(Q, dtype=float)
        self.R = np.asarray(R_acc, dtype=float)
        self.R_mag = np.asarray(R_mag, dtype=float)
        nominal = TriadErrors.nominal(self.batch_size)
        self.gyro_errors = gyro_errors if gyro_errors is not None else nominal
        self.accel_errors = accel_errors if accel_errors is not None else nominal
        self.mag_errors = mag_errors if mag_errors is not None else nominal
        if self.Q.shape != (9, 9) or self.R.shape != (3, 3) or self.R_mag.shape != (3, 3):
            raise ValueError(
                f"Q must be 9x9 and R_acc, R_mag 3x3, got {self.Q.shape}, {self.R.shape}, {self.R_mag.shape}"
            )

    @property
    def measurement_groups(self) -> dict[str, tuple[str, ...]]:
        """The accelerometer (the primary measurement); the magnetometer is the sensor ``mag``."""
        return {"accelerometer": self.measurement_names}

    @property
    def sensors(self):  # type: ignore[override]
        return {"mag": MeasurementModel(self.h_mag, self.R_mag, ("mag_x", "mag_y", "mag_z"))}

    def _per_run_arrays(self) -> tuple[str, ...]:
        return ("gyro_errors", "accel_errors", "mag_errors")

    # --- the error state ---

    @property
    def n_err(self) -> int:
        return 9

    @property
    def error_names(self) -> tuple[str, ...]:
        return ERROR_NAMES

    @property
    def error_units(self) -> tuple[str, ...]:
        return ERROR_UNITS

    def boxplus(self, x: np.ndarray, dx: np.ndarray) -> np.ndarray:
        shape = np.broadcast_shapes(x.shape[:-1], dx.shape[:-1])
        q = quat.boxplus(np.broadcast_to(x[..., :4], (*shape, 4)), np.broadcast_to(dx[..., :3], (*shape, 3)))
        return np.concatenate([q, x[..., 4:] + dx[..., 3:]], axis=-1)

    def boxminus(self, y: np.ndarray, x: np.ndarray) -> np.ndarray:
        shape = np.broadcast_shapes(x.shape[:-1], y.shape[:-1])
        d = quat.boxminus(np.broadcast_to(y[..., :4], (*shape, 4)), np.broadcast_to(x[..., :4], (*shape, 4)))
        return np.concatenate([d, y[..., 4:] - x[..., 4:]], axis=-1)

    # --- model functions ---

    def _gyro_correction(self, rate: np.ndarray) -> np.ndarray:
        """``C`` (B, K, 3, 3): the inverse of the gyro's known ``I + S + M + diag(S± ⊙ sgn)``,
        the sign taken from the bias-corrected sample (where the sign of a component flips, its
        rate is near zero and so is the asymmetry term)."""
        e = self.gyro_errors
        M = e.matrix[:, None] + np.einsum("bki,ij->bkij", e.asymmetry[:, None] * np.sign(rate), np.eye(3))
        return np.linalg.inv(M)

    def _body_rate(self, x: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        raw = u[:, None, 0:3] - x[..., 4:7]
        C = self._gyro_correction(raw)
        return np.einsum("bkij,bkj->bki", C, raw), C

    def f(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        omega, _ = self._body_rate(x, u)
        q = quat.normalize(quat.multiply(x[..., :4], quat.exp(omega * self.dt)))
        return np.concatenate([q, x[..., 4:]], axis=-1)

    def specific_force(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """``R(q)ᵀ (a_e − g_e)`` (B, K, 3): what an ideal accelerometer measures."""
        s = u[:, None, 3:6] - self.gravity_earth
        return quat.rotate(quat.conjugate(x[..., :4]), np.broadcast_to(s, (*x.shape[:-1], 3)))

    def h(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        return _apply_without_bias(self.accel_errors, self.specific_force(x, u)) + x[..., 7:10]

    def field_in_body(self, x: np.ndarray) -> np.ndarray:
        """``R(q)ᵀ m_e`` (B, K, 3)."""
        return quat.rotate(quat.conjugate(x[..., :4]), np.broadcast_to(self.mag_earth, (*x.shape[:-1], 3)))

    def h_mag(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        return self.mag_errors.apply(self.field_in_body(x))

    # --- analytic error-state Jacobians ---

    def F_err_analytic(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        omega, C = self._body_rate(x[:, None], u)
        phi = omega[:, 0] * self.dt
        B = x.shape[0]
        J = np.broadcast_to(np.eye(9), (B, 9, 9)).copy()
        J[:, 0:3, 0:3] = np.swapaxes(quat.rotation_matrix(quat.exp(phi)), -1, -2)
        J[:, 0:3, 3:6] = -self.dt * quat.right_jacobian(phi) @ C[:, 0]
        return J

    def H_err_analytic(self, x: np.ndarray, u: np.ndarray, sensor: str | None = None) -> np.ndarray:
        B = x.shape[0]
        J = np.zeros((B, 3, 9))
        if sensor is None:
            f_b = self.specific_force(x[:, None], u)[:, 0]
            J[:, :, 0:3] = self.accel_errors.jacobian(f_b) @ quat.skew(f_b)
            J[:, :, 6:9] = np.eye(3)
        elif sensor == "mag":
            m_b = self.field_in_body(x[:, None])[:, 0]
            J[:, :, 0:3] = self.mag_errors.jacobian(m_b) @ quat.skew(m_b)
        else:
            raise KeyError(sensor)
        return J

    def reset_jacobian(self, x: np.ndarray, dx: np.ndarray) -> np.ndarray:
        """``G = blockdiag(J_r(δθ), I, I)`` (Solà eqs. 284–287 with the exact right Jacobian: the
        new error ``δθ'`` satisfies ``exp(δθ̂ + e) = exp(δθ̂) ⊗ exp(δθ')``)."""
        G = np.broadcast_to(np.eye(9), (dx.shape[0], 9, 9)).copy()
        G[:, 0:3, 0:3] = quat.right_jacobian(dx[:, 0:3])
        return G

    # --- the truth ---

    @staticmethod
    def truth_state(angles: np.ndarray, gyro_bias: np.ndarray, accel_bias: np.ndarray) -> np.ndarray:
        """Filter state (..., 10) from ZYX Euler angles (roll, pitch, yaw) and the true biases."""
        return np.concatenate([quat.from_euler(angles), gyro_bias, accel_bias], axis=-1)


def _apply_without_bias(errors: TriadErrors, y: np.ndarray) -> np.ndarray:
    """The deterministic errors of a triad whose bias is a filter state: ``apply(y) − b0``."""
    return errors.apply(y) - errors.bias[(slice(None),) + (None,) * (y.ndim - 2)]
