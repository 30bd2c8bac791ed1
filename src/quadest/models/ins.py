"""``model=ins``: strapdown inertial navigation with aiding sensors at their own rates (seed 004's
15-state INS error filter, on the shared quadrotor; docs/ins.md).

State ``x = [q (4, scalar first, body → earth), p (3), v (3), b_g (3), b_a (3)]`` (n = 16), earth
frame z up; error state ``δx = [δθ (3, body frame), δp, δv, δb_g, δb_a]`` (n_err = 15) with
``x ⊞ δx = [q ⊗ e(δθ), p + δp, v + δv, b_g + δb_g, b_a + δb_a]`` (right perturbation, Solà 2017
§7). The attitude chart ``e`` is the rotation vector (``exp``) or, as seed 004, modified
Rodrigues parameters scaled by 4 (``e(δ) = from_mrp(δ/4)``, Crassidis & Markley 2003's
``f = 2(a + 1) = 4``), which agree with the rotation vector to first order, so both charts share
``Q``, ``P0`` and the Jacobians below.

Input ``u = [ω̃ (3), f̃ (3)]``: the gyro and accelerometer samples, each the mean over the step
that follows it (a Δθ/Δv-output IMU; Savage 1998, JGCD 21(1)). Mechanisation over one step
(Savage 1998's first-order algorithm with the attitude at mid-interval for the velocity):

    ω = C_g (ω̃ − b_g),  â = C_a (f̃ − b_a),  φ = ω T
    q⁺ = q ⊗ exp(φ),  a_e = R(q ⊗ exp(φ/2)) â + g_e,  g_e = [0, 0, −g]
    v⁺ = v + T a_e,  p⁺ = p + T v + ½ T² a_e,  b⁺ = b

``C_g``, ``C_a`` undo each run's known scale-factor/misalignment/asymmetry errors
(:meth:`~quadest.sensors.mimu.TriadErrors.correction`; identity unless calibrated). The update is
exact for a constant body rate and a specific force along the rotation axis.

Error-state transition (derivation in docs/ins.md; finite differences on the manifold check it),
with ``R_h = R(exp(φ/2))``, ``R_m = R(q) R_h``:

    δθ⁺ = Exp(φ)ᵀ δθ − T J_r(φ) C_g δb_g
    δa  = −R(q)[R_h â]× δθ + R_m [â]× J_r(φ/2) (T/2) C_g δb_g − R_m C_a δb_a
    δv⁺ = δv + T δa,  δp⁺ = δp + T δv + ½ T² δa

The model has no primary measurement (``m = 0``): the IMU is the input and every aiding sensor is
a further sensor (:class:`~quadest.sensors.base.SensorModel`, reading the state through
:func:`ins_layout`) updated when its sample is available.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from quadest.models.attitude import AttitudeMetrics
from quadest.models.base import FilterModel, MeasurementModel
from quadest.numerics import quaternion as quat
from quadest.sensors.base import SensorModel, StateLayout
from quadest.sensors.mimu import TriadErrors

CHARTS = ("rotation_vector", "mrp")
STATE_NAMES = ("qw", "qx", "qy", "qz", "x", "y", "z", "vx", "vy", "vz") + tuple(
    f"{b}_{a}" for b in ("bg", "ba") for a in "xyz"
)
STATE_UNITS = ("-",) * 4 + ("m",) * 3 + ("m/s",) * 3 + ("rad/s",) * 3 + ("m/s^2",) * 3
ERROR_NAMES = ("dtheta_x", "dtheta_y", "dtheta_z") + STATE_NAMES[4:]
ERROR_UNITS = ("rad",) * 3 + STATE_UNITS[4:]
ATT, POS, VEL, BG, BA = slice(0, 4), slice(4, 7), slice(7, 10), slice(10, 13), slice(13, 16)
PLATFORM = slice(6, 9)  # the input's platform position (after the IMU's 6), with a moving platform


def ins_layout(platform_input: bool = False) -> StateLayout:
    """The quantities the INS offers its aiding sensors (:mod:`quadest.sensors.base`): attitude,
    position and velocity, each moved one to one by its error-state block (``δθ`` is the
    body-frame rotation vector of the right perturbation), and with ``platform_input`` the
    moving platform's position from the input."""
    return StateLayout(
        n_err=15,
        state={"attitude": ATT, "position": POS, "velocity": VEL},
        error={"attitude": slice(0, 3), "position": slice(3, 6), "velocity": slice(6, 9)},
        inputs={"platform_position": PLATFORM} if platform_input else {},
    )


class InsFilterModel(AttitudeMetrics, FilterModel):
    """Strapdown INS with aiding sensors (see the module docstring).

    Args:
        sample_period: T (s), the IMU period.
        gravity: g (m/s²), along −z of the earth frame.
        Q: (15, 15) error-state process noise per step.
        aiding: the aiding sensors by name, in update order.
        gyro_errors, accel_errors: the known deterministic errors per run (their biases are not
            used: the biases are states); ``None`` for the nominal, error-free triads.
        chart: ``"rotation_vector"`` or ``"mrp"`` (the attitude error's coordinates).
        batch_size: runs the model is bound to.
        platform_input: the input carries the known position of a moving beacon platform after the
            IMU sample, ``u = [ω̃, f̃, p_P]`` (nu = 9; :class:`~quadest.sensors.vision.VisionAiding`,
            docs/seed004-landing.md); the mechanisation ignores it.
    """

    name = "ins"
    n = 16
    m = 0
    nu = 6
    state_names = STATE_NAMES
    state_units = STATE_UNITS
    measurement_names = ()

    def __init__(
        self,
        sample_period: float,
        gravity: float,
        Q: np.ndarray,
        aiding: Mapping[str, SensorModel],
        gyro_errors: TriadErrors | None = None,
        accel_errors: TriadErrors | None = None,
        chart: str = "rotation_vector",
        batch_size: int = 1,
        platform_input: bool = False,
    ) -> None:
        if chart not in CHARTS:
            raise ValueError(f"chart must be one of {CHARTS}, got {chart!r}")
        self.dt = float(sample_period)
        self.gravity_earth = np.array([0.0, 0.0, -float(gravity)])
        self.Q = np.asarray(Q, dtype=float)
        if self.Q.shape != (15, 15):
            raise ValueError(f"Q must be 15x15, got {self.Q.shape}")
        self.R = np.zeros((0, 0))
        self.aiding = dict(aiding)
        self.batch_size = batch_size
        self.gyro_errors = gyro_errors if gyro_errors is not None else TriadErrors.nominal(batch_size)
        self.accel_errors = accel_errors if accel_errors is not None else TriadErrors.nominal(batch_size)
        self.chart = chart
        self.nu = 9 if platform_input else 6

    @property
    def sensors(self):  # type: ignore[override]
        return {name: MeasurementModel(s.h, s.R, s.names, groups=s.groups) for name, s in self.aiding.items()}

    def _per_run_arrays(self) -> tuple[str, ...]:
        return ("gyro_errors", "accel_errors")

    def select(self, runs: int | slice | np.ndarray) -> InsFilterModel:
        other = super().select(runs)
        idx = slice(runs, runs + 1) if isinstance(runs, int | np.integer) else runs
        other.aiding = {name: s.select(idx) for name, s in self.aiding.items()}
        return other

    # --- the error state ---

    @property
    def n_err(self) -> int:
        return 15

    @property
    def error_names(self) -> tuple[str, ...]:
        return ERROR_NAMES

    @property
    def error_units(self) -> tuple[str, ...]:
        return ERROR_UNITS

    def _attitude_chart(self, dtheta: np.ndarray) -> np.ndarray:
        return quat.exp(dtheta) if self.chart == "rotation_vector" else quat.from_mrp(0.25 * dtheta)

    def _attitude_coordinates(self, dq: np.ndarray) -> np.ndarray:
        return quat.log(dq) if self.chart == "rotation_vector" else 4.0 * quat.to_mrp(dq)

    def boxplus(self, x: np.ndarray, dx: np.ndarray) -> np.ndarray:
        shape = np.broadcast_shapes(x.shape[:-1], dx.shape[:-1])
        q = quat.multiply(np.broadcast_to(x[..., ATT], (*shape, 4)), self._attitude_chart(dx[..., 0:3]))
        return np.concatenate([np.broadcast_to(q, (*shape, 4)), x[..., 4:] + dx[..., 3:]], axis=-1)

    def boxminus(self, y: np.ndarray, x: np.ndarray) -> np.ndarray:
        shape = np.broadcast_shapes(x.shape[:-1], y.shape[:-1])
        dq = quat.multiply(quat.conjugate(np.broadcast_to(x[..., ATT], (*shape, 4))), y[..., ATT])
        return np.concatenate([self._attitude_coordinates(dq), y[..., 4:] - x[..., 4:]], axis=-1)

    def f_noise(self, x: np.ndarray, w: np.ndarray, u: np.ndarray) -> np.ndarray:
        """The process noise acts on the error state: ``f(x, u) ⊞ w``."""
        return self.boxplus(self.f(x, u), w)

    # --- mechanisation ---

    def _corrected_imu(self, x: np.ndarray, u: np.ndarray):
        """``(ω, â, C_g, C_a)`` at points ``x`` (B, K, 16) for the IMU sample ``u`` (B, 6)."""
        raw_g = u[:, None, 0:3] - x[..., BG]
        raw_a = u[:, None, 3:6] - x[..., BA]
        C_g, C_a = self.gyro_errors.correction(raw_g), self.accel_errors.correction(raw_a)
        omega = np.einsum("bkij,bkj->bki", C_g, raw_g)
        accel = np.einsum("bkij,bkj->bki", C_a, raw_a)
        return omega, accel, C_g, C_a

    def f(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        omega, accel, _, _ = self._corrected_imu(x, u)
        T, q = self.dt, x[..., ATT]
        phi = omega * T
        a_e = quat.rotate(quat.multiply(q, quat.exp(0.5 * phi)), accel) + self.gravity_earth
        out = np.empty(x.shape)
        out[..., ATT] = quat.normalize(quat.multiply(q, quat.exp(phi)))
        out[..., POS] = x[..., POS] + T * x[..., VEL] + 0.5 * T**2 * a_e
        out[..., VEL] = x[..., VEL] + T * a_e
        out[..., 10:] = x[..., 10:]
        return out

    def h(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """No primary measurement: an empty (B, K, 0) array."""
        return np.zeros((*x.shape[:-1], 0))

    def F_err_analytic(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        omega, accel, C_g, C_a = (a[:, 0] for a in self._corrected_imu(x[:, None], u))
        T, B = self.dt, x.shape[0]
        phi = omega * T
        R_q = quat.rotation_matrix(x[:, ATT])
        R_h = quat.rotation_matrix(quat.exp(0.5 * phi))
        R_m = R_q @ R_h
        d_theta = -R_q @ quat.skew(np.einsum("bij,bj->bi", R_h, accel))
        d_bg = R_m @ quat.skew(accel) @ quat.right_jacobian(0.5 * phi) @ C_g * (0.5 * T)
        d_ba = -R_m @ C_a
        J = np.broadcast_to(np.eye(15), (B, 15, 15)).copy()
        J[:, 0:3, 0:3] = np.swapaxes(quat.rotation_matrix(quat.exp(phi)), -1, -2)
        J[:, 0:3, 9:12] = -T * quat.right_jacobian(phi) @ C_g
        J[:, 3:6, 6:9] = T * np.eye(3)
        for rows, gain in ((slice(3, 6), 0.5 * T**2), (slice(6, 9), T)):
            J[:, rows, 0:3] = gain * d_theta
            J[:, rows, 9:12] = gain * d_bg
            J[:, rows, 12:15] = gain * d_ba
        return J

    def H_err_analytic(self, x: np.ndarray, u: np.ndarray, sensor: str | None = None) -> np.ndarray:
        if sensor is None:
            return np.zeros((x.shape[0], 0, 15))
        return self.aiding[sensor].jacobian(x, u)

    # --- the truth and the reported errors ---

    @staticmethod
    def truth_state(
        angles: np.ndarray, position: np.ndarray, velocity: np.ndarray, gyro_bias: np.ndarray, accel_bias: np.ndarray
    ) -> np.ndarray:
        """Filter state (..., 16) from ZYX Euler angles (roll, pitch, yaw), position, velocity and
        the true biases."""
        return np.concatenate([quat.from_euler(angles), position, velocity, gyro_bias, accel_bias], axis=-1)
