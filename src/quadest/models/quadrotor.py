"""Quadrotor filter models: the thesis's 6-state formulation and an augmented 9-state one.

``thesis`` (seed 000, eq. 5.30): ``x = [ẋ ẏ ż φ̇ θ̇ ψ̇]``. The Euler angles the equations need are
*companions*: integrated outside the filter from the estimated rates, as the thesis does
("integrate X_k to obtain position and Euler angles", §5.3.1). The filter's input is therefore
``u = [Ω1..Ω4, φ, θ, ψ]``.

``augmented``: ``x = [ẋ ẏ ż φ θ ψ φ̇ θ̇ ψ̇]``, angles in the state, input ``u = [Ω1..Ω4]``.

Both discretise with the sample period T (eq. 5.32, forward Euler):

- ``v⁺ = v + T (R(Θ) e_z U1/m − g e_z − Kt v/m)``
- ``Θ̇⁺ = Θ̇ + T Θ̈(Θ, Θ̇, Ω)`` with ``Θ̈`` from eq. 5.31 (see :func:`euler_angle_accel`)
- ``Θ⁺ = Θ + T Θ̇`` (augmented only)

The measurement is the MIMU, ``z = [accelerometer (3), gyro (3)]``: the specific force
``e_z U1/m − Rᵀ Kt v/m`` and the body rates ``W(Θ) Θ̇``, passed through the sensor's
deterministic error model. With ``calibrated`` the filter knows each run's drawn errors (the
thesis's premise that the measurement equation accounts for them); otherwise it assumes nominal,
error-free sensors (a mismatch experiment).
"""

from __future__ import annotations

from collections.abc import Mapping
from functools import cache
from types import ModuleType

import numpy as np

from quadest.models.base import FilterModel, MeasurementModel
from quadest.numerics.square_root import kernel_backend
from quadest.quadrotor.dynamics import (
    body_rates,
    euler_angle_accel_from_inputs,
    euler_rates,
    rotor_inputs,
    specific_force,
    translational_accel,
)
from quadest.quadrotor.kinematics import (
    matvec,
    rate_matrix,
    rate_matrix_inv,
    rate_matrix_inv_partials,
    rotation,
)
from quadest.quadrotor.params import QuadrotorParams
from quadest.sensors.base import SensorModel, StateLayout
from quadest.sensors.mimu import TriadErrors

FORMULATIONS = ("thesis", "augmented")


@cache
def _kernels() -> ModuleType | None:
    """The compiled ``f``/``h``, or ``None`` when numba cannot be imported."""
    try:
        from quadest.models import quadrotor_kernels
    except ImportError:
        return None
    return quadrotor_kernels


def packed_params(params: QuadrotorParams) -> np.ndarray:
    """``[b, d, l b, m, g, Jr, Kt (3), I (3), Kr (3)]``, the parameters as the compiled ``f``/``h`` take them."""
    return np.array(
        [
            params.thrust_factor,
            params.drag_factor,
            params.arm * params.thrust_factor,
            params.mass,
            params.gravity,
            params.rotor_inertia,
            *params.translational_drag,
            *params.inertia,
            *params.rotational_drag,
        ]
    )


_V = ("vx", "vy", "vz")
_ANG = ("phi", "theta", "psi")
_RATE = ("phi_dot", "theta_dot", "psi_dot")
_POS = ("x", "y", "z")


def quadrotor_layout(formulation: str) -> StateLayout:
    """The quantities the quadrotor filters offer further sensors (:mod:`quadest.sensors.base`):
    the earth-frame velocity, the first three states of both formulations. Position and, in
    ``thesis``, the angles are companions integrated outside the filter, so no sensor can correct
    them."""
    n = len(QuadrotorFilterModel.formulation_state_names(formulation))
    return StateLayout(n_err=n, state={"velocity": slice(0, 3)}, error={"velocity": slice(0, 3)})


class QuadrotorFilterModel(FilterModel):
    """Filter model of the quadrotor with a MIMU, bound to a batch of Monte Carlo runs.

    Args:
        params: physical parameters the filter assumes.
        formulation: ``"thesis"`` or ``"augmented"``.
        sample_period: T (s).
        Q, R: process and measurement noise covariances.
        accel_errors, gyro_errors: deterministic sensor errors the filter assumes, per run.
        aiding: further sensors by name, in update order (``model.aiding``, docs/sensors.md), on
            :func:`quadrotor_layout`; none by default.
    """

    fused_unscented = True

    def __init__(
        self,
        params: QuadrotorParams,
        formulation: str,
        sample_period: float,
        Q: np.ndarray,
        R: np.ndarray,
        accel_errors: TriadErrors,
        gyro_errors: TriadErrors,
        aiding: Mapping[str, SensorModel] | None = None,
    ) -> None:
        self.aiding = dict(aiding or {})
        self.state_names = self.formulation_state_names(formulation)
        self.name = f"quadrotor_{formulation}"
        self.params = params
        self.formulation = formulation
        self.thesis = formulation == "thesis"
        self.dt = sample_period
        self.accel_errors = accel_errors
        self.gyro_errors = gyro_errors
        self.batch_size = accel_errors.bias.shape[0]
        if self.thesis:
            self.companion_names = _POS + _ANG
            self.companion_units = ("m",) * 3 + ("rad",) * 3
            self.nu = 7
        else:
            self.companion_names = _POS
            self.companion_units = ("m",) * 3
            self.nu = 4
        self.n = len(self.state_names)
        self.state_units = tuple("m/s" if s in _V else "rad" if s in _ANG else "rad/s" for s in self.state_names)
        self.measurement_names = ("acc_x", "acc_y", "acc_z", "gyro_p", "gyro_q", "gyro_r")
        self.m = 6
        self.Q = np.asarray(Q, dtype=float)
        self.R = np.asarray(R, dtype=float)
        self._rate_slice = slice(3, 6) if self.thesis else slice(6, 9)
        self._packed = packed_params(params)

    @staticmethod
    def formulation_state_names(formulation: str) -> tuple[str, ...]:
        """The filter state of a formulation, without building a model: ``thesis`` (6) or
        ``augmented`` (9)."""
        if formulation not in FORMULATIONS:
            raise ValueError(f"formulation must be one of {FORMULATIONS}, got {formulation!r}")
        return _V + _RATE if formulation == "thesis" else _V + _ANG + _RATE

    def _per_run_arrays(self) -> tuple[str, ...]:
        return ("accel_errors", "gyro_errors")

    @property
    def measurement_groups(self) -> dict[str, tuple[str, ...]]:
        """The MIMU's two triads, each judged by its own NIS."""
        return {"accelerometer": self.measurement_names[:3], "gyro": self.measurement_names[3:]}

    # --- further sensors (model.aiding) ---

    @property
    def sensors(self):  # type: ignore[override]
        return {name: MeasurementModel(s.h, s.R, s.names, groups=s.groups) for name, s in self.aiding.items()}

    def select(self, runs: int | slice | np.ndarray) -> QuadrotorFilterModel:
        other = super().select(runs)
        idx = slice(runs, runs + 1) if isinstance(runs, int | np.integer) else runs
        other.aiding = {name: s.select(idx) for name, s in self.aiding.items()}
        return other

    def H_err_analytic(self, x: np.ndarray, u: np.ndarray, sensor: str | None = None) -> np.ndarray | None:
        """A further sensor's analytic Jacobian; ``None`` for the MIMU (then :meth:`H`)."""
        return None if sensor is None else self.aiding[sensor].jacobian(x, u)

    def measurement_jacobian(self, sensor: str | None, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        return self.H(x, u) if sensor is None else self.aiding[sensor].jacobian(x, u)

    # --- mapping from the 16-state truth ---

    def truth_to_state(self, truth: np.ndarray) -> np.ndarray:
        """Filter state of the truth (..., 16) → (..., n)."""
        v, angles, omega = truth[..., 3:6], truth[..., 6:9], truth[..., 9:12]
        rates = euler_rates(angles, omega)
        parts = [v, rates] if self.thesis else [v, angles, rates]
        return np.concatenate(parts, axis=-1)

    def truth_to_companion(self, truth: np.ndarray) -> np.ndarray:
        """Companion values of the truth (..., 16) → (..., len(companion_names))."""
        return truth[..., 0:9].take([0, 1, 2, 6, 7, 8] if self.thesis else [0, 1, 2], axis=-1)

    # --- companions (thesis §5.3.1: integrate the estimate) ---

    def filter_input(self, u: np.ndarray, companion: np.ndarray) -> np.ndarray:
        return np.concatenate([u, companion[:, 3:6]], axis=-1) if self.thesis else u

    def companion_step(self, companion: np.ndarray, x_post: np.ndarray) -> np.ndarray:
        out = companion.copy()
        out[:, 0:3] += self.dt * x_post[:, 0:3]
        if self.thesis:
            out[:, 3:6] += self.dt * x_post[:, 3:6]
        return out

    # --- model functions ---

    def _split(self, x: np.ndarray, u: np.ndarray):
        speeds = u[:, None, 0:4]
        if self.thesis:  # the same angles for every point of a run: trig once per run
            return x[..., 0:3], u[:, None, 4:7], x[..., 3:6], speeds
        return x[..., 0:3], x[..., 3:6], x[..., 6:9], speeds

    def _compiled(self, x: np.ndarray, u: np.ndarray) -> ModuleType | None:
        """The compiled ``f``/``h`` (:mod:`quadest.models.quadrotor_kernels`) for real sigma points
        (B, K, n) of this model's runs on the ``numba`` backend; ``None`` sends the call to numpy
        (complex steps, other shapes, ``QUADEST_KERNELS=numpy``)."""
        if x.dtype != np.float64 or u.dtype != np.float64 or x.ndim != 3 or u.shape != (x.shape[0], self.nu):
            return None
        if x.shape[0] != self.batch_size or kernel_backend() != "numba":
            return None
        return _kernels()

    def warm_up_kernels(self) -> None:
        """Load the compiled ``f``/``h`` now (see :func:`quadest.numerics.square_root.warm_up`)."""
        x, u = np.zeros((self.batch_size, 1, self.n)), np.zeros((self.batch_size, self.nu))
        self.f(x, u)
        self.h(x, u)

    def f(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """One step of the model (eq. 5.32): compiled for real sigma points, else :meth:`f_numpy`."""
        kernels = self._compiled(x, u)
        if kernels is None:
            return self.f_numpy(x, u)
        out = np.empty_like(x, order="C")
        kernels.quadrotor_f(np.ascontiguousarray(x), np.ascontiguousarray(u), self._packed, self.thesis, self.dt, out)
        return out

    def f_numpy(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """The numpy reference of :meth:`f` (any dtype, complex steps included)."""
        v, angles, rates, speeds = self._split(x, u)
        U, omega_r = rotor_inputs(self.params, speeds)
        T = self.dt
        out = np.empty(x.shape, dtype=np.result_type(x, u))
        out[..., 0:3] = v + T * translational_accel(self.params, angles, v, U[..., 0])
        out[..., self._rate_slice] = rates + T * euler_angle_accel_from_inputs(
            self.params, angles, rates, U[..., 1:], omega_r
        )
        if not self.thesis:
            out[..., 3:6] = angles + T * rates
        return out

    def _ideal_measurement(self, x: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        v, angles, rates, speeds = self._split(x, u)
        U, _ = rotor_inputs(self.params, speeds)
        acc = specific_force(self.params, angles, v, U[..., 0])
        gyro = body_rates(angles, rates)
        return acc, gyro

    def h(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """The MIMU measurement: compiled for real sigma points, else :meth:`h_numpy`."""
        kernels = self._compiled(x, u)
        if kernels is None:
            return self.h_numpy(x, u)
        out = np.empty((*x.shape[:2], self.m))
        a, g = self.accel_errors, self.gyro_errors
        kernels.quadrotor_h(
            np.ascontiguousarray(x),
            np.ascontiguousarray(u),
            self._packed,
            self.thesis,
            *(np.ascontiguousarray(arr) for arr in (a.matrix, a.asymmetry, a.bias, g.matrix, g.asymmetry, g.bias)),
            out,
        )
        return out

    def h_numpy(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """The numpy reference of :meth:`h` (any dtype, complex steps included)."""
        acc, gyro = self._ideal_measurement(x, u)
        return np.concatenate([self.accel_errors.apply(acc), self.gyro_errors.apply(gyro)], axis=-1)

    # --- Jacobians ---

    def _rate_accel_jacobian(self, angles: np.ndarray, rates: np.ndarray, speeds: np.ndarray) -> np.ndarray:
        """``∂Θ̈/∂Θ̇`` (B, 3, 3) at fixed angles, analytic.

        ``Θ̈ = Ẇ⁻¹ ω + W⁻¹ ω̇(ω)``, ``ω = W Θ̇``, ``Ẇ⁻¹ = ∂W⁻¹/∂φ φ̇ + ∂W⁻¹/∂θ θ̇``, so
        ``∂Θ̈/∂Θ̇ = [∂W⁻¹/∂φ ω, ∂W⁻¹/∂θ ω, 0] + Ẇ⁻¹ W + W⁻¹ (∂ω̇/∂ω) W``.
        """
        p = self.params
        W = rate_matrix(angles)
        W_inv = rate_matrix_inv(angles)
        omega = body_rates(angles, rates)
        d_phi, d_theta = rate_matrix_inv_partials(angles)
        w_inv_dot = d_phi * rates[:, 0, None, None] + d_theta * rates[:, 1, None, None]
        first = np.zeros((*omega.shape, 3), dtype=omega.dtype)
        first[..., :, 0] = matvec(d_phi, omega)
        first[..., :, 1] = matvec(d_theta, omega)
        ix, iy, iz = p.inertia
        kr = p.kr
        _, omega_r = rotor_inputs(p, speeds)
        jw = p.rotor_inertia * omega_r
        pp, qq, rr = omega[:, 0], omega[:, 1], omega[:, 2]
        J_wdot = np.empty_like(first)
        J_wdot[:, 0, 0], J_wdot[:, 0, 1], J_wdot[:, 0, 2] = -kr[0] / ix, ((iy - iz) * rr - jw) / ix, (iy - iz) * qq / ix
        J_wdot[:, 1, 0], J_wdot[:, 1, 1], J_wdot[:, 1, 2] = ((iz - ix) * rr + jw) / iy, -kr[1] / iy, (iz - ix) * pp / iy
        J_wdot[:, 2, 0], J_wdot[:, 2, 1], J_wdot[:, 2, 2] = (ix - iy) * qq / iz, (ix - iy) * pp / iz, -kr[2] / iz
        return first + w_inv_dot @ W + W_inv @ J_wdot @ W

    def _complex_step_columns(self, fun, x: np.ndarray, u: np.ndarray, cols: range) -> np.ndarray:
        """Columns ``cols`` of the Jacobian of ``fun`` by the complex step (exact to round-off)."""
        step = 1e-30
        pts = np.repeat(x[:, None, :].astype(complex), len(cols), axis=1)
        for i, j in enumerate(cols):
            pts[:, i, j] += 1j * step
        return np.swapaxes(fun(pts, u).imag / step, -1, -2)

    def F_analytic(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Jacobian of ``f`` (B, n, n).

        Velocity and rate columns are analytic; for ``augmented`` the three angle columns
        (derivatives of R(Θ) and of W⁻¹(Θ) and its derivatives) come from the complex step,
        which is exact to round-off.
        """
        _v, angles, rates, speeds = self._split(x[:, None, :], u)
        B, n, T = x.shape[0], self.n, self.dt
        J = np.broadcast_to(np.eye(n), (B, n, n)).copy()
        J[:, 0:3, 0:3] -= T * np.diag(self.params.kt / self.params.mass)
        rs = self._rate_slice
        J[:, rs, rs] += T * self._rate_accel_jacobian(angles[:, 0], rates[:, 0], speeds[:, 0])
        if not self.thesis:
            J[:, 3:6, 6:9] += T * np.eye(3)
            J[:, :, 3:6] = self._complex_step_columns(self.f, x, u, range(3, 6))
        return J

    def H_analytic(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Jacobian of ``h`` (B, 6, n): analytic in velocity and rates, complex step in angles."""
        _v, angles, _rates, _speeds = self._split(x[:, None, :], u)
        acc, gyro = self._ideal_measurement(x[:, None, :], u)
        B = x.shape[0]
        J = np.zeros((B, 6, self.n))
        R = rotation(angles[:, 0])
        d_acc_dv = -np.swapaxes(R, -1, -2) * (self.params.kt / self.params.mass)
        J[:, 0:3, 0:3] = self.accel_errors.jacobian(acc[:, 0]) @ d_acc_dv
        J[:, 3:6, self._rate_slice] = self.gyro_errors.jacobian(gyro[:, 0]) @ rate_matrix(angles[:, 0])
        if not self.thesis:
            J[:, :, 3:6] = self._complex_step_columns(self.h, x, u, range(3, 6))
        return J
