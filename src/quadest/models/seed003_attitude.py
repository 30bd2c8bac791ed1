"""``model=seed003_attitude``: seed 003's reduced 5-state filter, mapped onto the shared quadrotor.

Seed 003 (Cao, Liu & Li, EKF-based state estimation inside a backstepping control loop) filters
five states ``x_F = (α, β, p, q, r)`` of a **fixed-wing** UAV: the airflow angles (angle of attack
α, sideslip β) and the body rates, the states "most affected by sensor noise" (its eq. 7). It
measures those five states directly (``y_F ∈ R⁵``, ``H = I``), with the noise of typical low-cost
sensors: σ = 5 °/s on the rates (Σ = 0.0076 I₃ rad²/s²) and σ = 2° on the airflow angles
(Σ = 0.0012 I₂ rad²); the EKF's transition matrix is the first-order ``Φ_k ≈ I + F_k T_s`` (its
eq. 11) of the continuous Jacobian ``F_k`` (its eq. 12). Its Q is not legible in the text.

A quadrotor has no airflow angles: our mapping puts **roll and pitch** (φ, θ) in their place, the
attitude states a quadrotor's backstepping loop flies on, so ``x = (φ, θ, p, q, r)`` with

- transition: one Euler step of the continuous dynamics, ``x_k = x_{k−1} + T ẋ(x_{k−1}, Ω_{k−1})``:
  ``φ̇ = p + tan θ (q sin φ + r cos φ)``, ``θ̇ = q cos φ − r sin φ`` (Euler-angle kinematics, which
  do not involve yaw) and ``ω̇`` from Euler's equation with the rotor gyroscopic term and rotational
  drag (:func:`quadest.quadrotor.dynamics.body_angular_accel`, the truth's own); the input ``Ω`` is
  the vehicle's rotor speeds (the seed's ``u`` enters its model directly; our motors lag their
  commands, so the speeds that make the torques are the input);
- Jacobian: ``Φ = I + T F`` with ``F = ∂ẋ/∂x`` analytic (seed 003 eq. 11);
- measurement: the five states, ``z = x + n``, ``H = I₅``, ``R`` from ``model.R`` (the seed's
  diag(0.0012, 0.0012, 0.0076, 0.0076, 0.0076) in the order (angles, rates)); the truth's noise is
  ``closed_loop.state_sensor`` (σ = 2°, 5 °/s), drawn from the run's ``state_sensor`` stream, the
  same draws the noisy-state controller reads (:mod:`quadest.closed_loop.seed003`);
- start: the first measurement, ``x0 = z_0``, with ``P0 = R``.

The Monte Carlo data (open loop, and the closed loop's shared flight) is built by
:mod:`quadest.simulation.seed003_attitude_data`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from quadest.config.closed_loop import ClosedLoopConf
from quadest.config.ranges import require_positive
from quadest.config.settings import DataSettings
from quadest.errors import ConfigError
from quadest.models.base import FilterModel
from quadest.models.config_checks import validate_quadrotor
from quadest.quadrotor.dynamics import body_angular_accel, body_rate_jacobian, euler_rates, rotor_inputs
from quadest.quadrotor.params import QuadrotorParams

SLOTS = np.array([6, 7, 9, 10, 11])  # φ, θ, p, q, r in the 16-state truth (and in the state sensor's 12 normals)
ROTORS = slice(12, 16)


class AttitudeRateModel(FilterModel):
    """Roll, pitch and body rates ``(φ, θ, p, q, r)``, rotor speeds (4) as input, the five states
    measured (seed 003 eqs 7–12 with roll and pitch in place of the airflow angles)."""

    name = "seed003_attitude"
    n, m, nu = 5, 5, 4
    state_names = ("phi", "theta", "p", "q", "r")
    state_units = ("rad", "rad", "rad/s", "rad/s", "rad/s")
    measurement_names = ("phi_meas", "theta_meas", "p_meas", "q_meas", "r_meas")

    def __init__(self, params: QuadrotorParams, dt: float, Q: np.ndarray, R: np.ndarray, batch_size: int) -> None:
        self.params, self.dt = params, dt
        self.Q, self.R = np.asarray(Q, dtype=float), np.asarray(R, dtype=float)
        self.batch_size = batch_size

    def derivative(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Continuous ``ẋ`` (B, K, 5) at ``x`` (B, K, 5) under rotor speeds ``u`` (B, 4)."""
        U, omega_r = rotor_inputs(self.params, u)
        out = np.empty_like(x)
        # euler_rates reads φ and θ of its angles only: x[..., :3] = (φ, θ, p) fills ψ's slot
        out[..., 0:2] = euler_rates(x[..., :3], x[..., 2:5])[..., :2]
        out[..., 2:5] = body_angular_accel(self.params, x[..., 2:5], U[:, None, 1:4], omega_r[:, None])
        return out

    def f(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        return x + self.dt * self.derivative(x, u)

    def h(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        return x.copy()

    def continuous_jacobian(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """``F = ∂ẋ/∂x`` (B, 5, 5) at ``x`` (B, 5) (seed 003 eq. 12, our states)."""
        phi, theta, p, q, r = x.T
        sf, cf, tt = np.sin(phi), np.cos(phi), np.tan(theta)
        J = np.zeros((x.shape[0], 5, 5))
        J[:, 0] = np.stack([tt * (q * cf - r * sf), (q * sf + r * cf) / np.cos(theta) ** 2, np.ones_like(p),
                            sf * tt, cf * tt], axis=-1)  # fmt: skip
        J[:, 1, 0], J[:, 1, 3], J[:, 1, 4] = -q * sf - r * cf, cf, -sf
        J[:, 2:5, 2:5] = body_rate_jacobian(self.params, x[:, 2:5], rotor_inputs(self.params, u)[1])
        return J

    def F_analytic(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """``Φ = I + T F`` (seed 003 eq. 11)."""
        return np.eye(5) + self.dt * self.continuous_jacobian(x, u)

    def H_analytic(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        return np.broadcast_to(np.eye(5), (x.shape[0], 5, 5)).copy()

    def truth_to_state(self, truth: np.ndarray) -> np.ndarray:
        """The filter state (..., 5) of a 16-state truth (..., 16)."""
        return truth[..., SLOTS]

    def truth_to_companion(self, truth: np.ndarray) -> np.ndarray:
        """No companion values: (..., 0)."""
        return truth[..., :0]


def sensor_std(closed_loop: ClosedLoopConf) -> np.ndarray:
    """(5,) one-sigma noise of the state sensor on (φ, θ, p, q, r), from ``closed_loop.state_sensor``."""
    s = closed_loop.state_sensor
    return np.array([s.angle, s.angle, s.rate, s.rate, s.rate])


def measure_states(truth: np.ndarray, normals: np.ndarray, std: np.ndarray) -> np.ndarray:
    """What the state sensor reads of a 16-state ``truth`` (..., 16): its five states plus ``std``
    times the standard normals ``normals`` (..., 12) at the same slots."""
    return truth[..., SLOTS] + std * normals[..., SLOTS]


def state_sensor_normals(streams: dict, samples: int) -> np.ndarray:
    """(B, K+1, 12) standard normals of the state sensor, one row of 12 per sample from each run's
    ``state_sensor`` stream: the draws of :func:`quadest.simulation.quadrotor_data.draw_plant`."""
    return np.stack([rng.standard_normal((samples, 12)) for rng in streams["state_sensor"]])


def seed003_filter_model(model: Any, sample_period: float, runs: int) -> AttitudeRateModel:
    """The filter model of the ``model`` settings (a
    :class:`~quadest.models.schemas.Seed003AttitudeModelConf`; Q and R diagonal from ``model.Q``,
    ``model.R``) at ``sample_period``, bound to ``runs`` runs."""
    from quadest.models.quadrotor_config import quadrotor_params

    return AttitudeRateModel(
        quadrotor_params(model), float(sample_period), np.diag(list(model.Q)), np.diag(list(model.R)), runs
    )


def validate_seed003_attitude(settings: DataSettings) -> None:
    """Range checks of ``model=seed003_attitude``: the quadrotor's, and Q and R, five positive
    variances each (a zero in R would make the posterior covariance singular)."""
    validate_quadrotor(settings)
    for key in ("Q", "R"):
        values = list(getattr(settings.model, key))
        if len(values) != 5:
            raise ConfigError(f"model.{key}", values, "five variances, in the order (phi, theta, p, q, r)")
    for i, (q, r) in enumerate(zip(settings.model.Q, settings.model.R, strict=True)):
        require_positive(f"model.Q[{i}]", q)
        require_positive(f"model.R[{i}]", r)


def one_step_error_variance(model: AttitudeRateModel, truth: np.ndarray) -> np.ndarray:
    """(5,) mean square of the filter's one-step model error along a flown 16-state ``truth``
    (B, K+1, 16): ``x_{k+1} − f(x_k, Ω_k)`` with the true states and rotor speeds, the error the
    process noise Q stands for."""
    x, u = model.truth_to_state(truth), truth[..., ROTORS]
    B, K = x.shape[0], x.shape[1] - 1
    predicted = model.f(x[:, :-1].reshape(B * K, 1, 5), u[:, :-1].reshape(B * K, 4)).reshape(B, K, 5)
    return np.nanmean((x[:, 1:] - predicted) ** 2, axis=(0, 1))
