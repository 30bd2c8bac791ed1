"""``model=pendulum``: a frictionless pendulum, angle θ and rate ω, its sine measured
(docs/models.md walks through this file; the tests register it as an out-of-tree plugin).

Forward Euler with the sample period T (as the quadrotor's eq. 5.32):

    θ⁺ = θ + T ω + w_θ,    ω⁺ = ω − T (g/l) sin θ + w_ω,    z = sin θ + v

with ``w ~ N(0, diag(angle_noise², rate_noise²))`` and ``v ~ N(0, measurement_noise²)``. The
truth is drawn from this same model (:func:`~quadest.simulation.validation_data.data_from_filter_model`),
so the PCRLB is a true bound.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from quadest.config.ranges import require_positive
from quadest.config.settings import DataSettings
from quadest.errors import ConfigError
from quadest.models.base import FilterModel
from quadest.montecarlo.data import sample_count
from quadest.montecarlo.initial import draw_initial_estimates
from quadest.montecarlo.streams import run_streams
from quadest.simulation.spec import ModelSpec
from quadest.simulation.validation_data import data_from_filter_model


@dataclass
class PendulumConf:
    """The ``model`` node of ``model=pendulum``: its schema, stored as ``/schema/model/pendulum``."""

    name: str = "pendulum"
    length: float = 1.0  # l, m
    gravity: float = 9.81  # g, m/s²
    angle_noise: float = 1.0e-4  # one-sigma of w_θ per step, rad
    rate_noise: float = 0.01  # one-sigma of w_ω per step, rad/s
    measurement_noise: float = 0.05  # one-sigma of v
    initial_state: list[float] = field(default_factory=lambda: [0.5, 0.0])  # θ0 (rad), ω0 (rad/s)
    initial_std: list[float] = field(default_factory=lambda: [0.2, 0.2])  # the filters' P0 = diag(std²)


class PendulumModel(FilterModel):
    """The filter model (module docstring), with analytic Jacobians ``F = [[1, T], [−T (g/l) cos θ, 1]]``
    and ``H = [cos θ, 0]``, bound to ``batch_size`` runs."""

    name = "pendulum"
    n, m, nu = 2, 1, 0
    state_names, state_units, measurement_names = ("theta", "omega"), ("rad", "rad/s"), ("sin_theta",)

    def __init__(self, m: PendulumConf, sample_period: float, batch_size: int) -> None:
        self.dt, self.batch_size = float(sample_period), batch_size
        self.w2 = float(m.gravity) / float(m.length)
        self.Q = np.diag([float(m.angle_noise) ** 2, float(m.rate_noise) ** 2])
        self.R = np.array([[float(m.measurement_noise) ** 2]])

    def f(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:  # x (B, K, 2)
        theta, omega = x[..., 0], x[..., 1]
        return np.stack([theta + self.dt * omega, omega - self.dt * self.w2 * np.sin(theta)], axis=-1)

    def h(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        return np.sin(x[..., :1])

    def F_analytic(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:  # x (B, 2)
        J = np.zeros((x.shape[0], 2, 2))
        J[:, 0, 0], J[:, 0, 1], J[:, 1, 1] = 1.0, self.dt, 1.0
        J[:, 1, 0] = -self.dt * self.w2 * np.cos(x[:, 0])
        return J

    def H_analytic(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        J = np.zeros((x.shape[0], 1, 2))
        J[:, 0, 0] = np.cos(x[:, 0])
        return J


def build_pendulum_data(settings: DataSettings):
    """``settings.runs`` runs from ``initial_state``; each filter starts from N(truth, P0).
    ``settings.model`` is a :class:`PendulumConf`."""
    m, runs, K = settings.model, int(settings.runs), sample_count(settings.duration, settings.sample_period)
    P0 = np.diag(np.square(np.array(m.initial_std, dtype=float)))
    x0 = np.broadcast_to(np.array(m.initial_state, dtype=float), (runs, 2))
    estimates = draw_initial_estimates(x0, P0, run_streams(int(settings.seed), runs, settings.first_run)["initial"])
    model = PendulumModel(m, settings.sample_period, runs)
    return data_from_filter_model(settings, model, x0, estimates, P0, np.zeros((runs, K + 1, 0)))


def validate_pendulum(settings: DataSettings) -> None:
    """Range checks: one line naming the key, the value and what is allowed."""
    m: PendulumConf = settings.model
    for key in ("length", "gravity", "angle_noise", "rate_noise", "measurement_noise"):
        require_positive(f"model.{key}", getattr(m, key))
    for key, values in (("initial_state", m.initial_state), ("initial_std", m.initial_std)):
        if len(values) != 2:
            raise ConfigError(f"model.{key}", list(values), "must list 2 values (theta, omega)")
    for i, std in enumerate(m.initial_std):
        require_positive(f"model.initial_std[{i}]", std)


MODEL = ModelSpec(
    "pendulum",
    PendulumConf,
    build_pendulum_data,
    state_dimension=lambda settings: 2,
    validate=validate_pendulum,
    pcrlb_is_bound=True,  # the truth is drawn from the filter model with its own Q and R
)
