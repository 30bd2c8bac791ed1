"""Monte Carlo data of ``model=bearings_only`` (:mod:`quadest.models.bearings_only`): the turning
target of the EKF/UKF toolbox manual's bearings-only demonstration (Hartikainen, Solin & Särkkä
2011, §3.6; the toolbox's ``demos/bot_demo``).

The truth has no process noise (the manual: "we also give the target a slightly randomized
acceleration, so that it achieves a curved trajectory, which is approximately the same in
different simulations"). It starts at ``x0`` and moves through ``x_k = exp(F(a_k) Δt) x_{k−1}``
with the coordinated-turn matrix of the toolbox demo,

    F(a) = [[0, 0, 1, 0], [0, 0, 0, 1], [0, 0, 0, a], [0, 0, −a, 0]],

that is ``ẍ = a ẏ``, ``ÿ = −a ẋ`` (a > 0 turns clockwise). The turn rate ``a_k`` is
``turn_angle / turn_steps / Δt + turn_rate_std · N(0, 1)`` on the ``turn_steps`` steps from each of
``turn_starts`` (the demo: π/2/51/Δt + 0.01 N(0, 1) on steps 50–100, 200–250 and 350–400, step 1 the
first transition) and 0 elsewhere. Its draws come from each run's ``process`` stream (three
segments in order), the bearing noise from its ``measurement`` stream
(:mod:`quadest.montecarlo.streams`): run ``i`` is the same whatever the number of runs.
"""

from __future__ import annotations

import numpy as np

from quadest.config.ranges import require_positive
from quadest.config.settings import DataSettings
from quadest.errors import ConfigError
from quadest.models.bearings_only import BearingsOnlyModel, BearingsOnlyModelConf
from quadest.montecarlo import MonteCarloData
from quadest.montecarlo.data import sample_count
from quadest.montecarlo.streams import run_seed_sequences, run_streams
from quadest.simulation.spec import ModelSpec
from quadest.simulation.validation_data import simulation_labels


def turn_transition(a: np.ndarray, dt: float) -> np.ndarray:
    """``exp(F(a) Δt)`` (..., 4, 4) for turn rates ``a`` (...), in closed form: the velocity
    rotates by ``−a Δt``, the position moves by its integral,

        v(Δt) = [[c, s], [−s, c]] v,   p(Δt) = p + [[s/a, (1 − c)/a], [−(1 − c)/a, s/a]] v,

    with ``c = cos(a Δt)``, ``s = sin(a Δt)``; ``s/a = Δt sinc(a Δt/π)`` and
    ``(1 − c)/a = (a Δt²/2) sinc(a Δt/2π)²`` (``np.sinc``) hold at ``a = 0`` too."""
    a = np.asarray(a, dtype=float)
    th = a * dt
    c, s = np.cos(th), np.sin(th)
    s_a = dt * np.sinc(th / np.pi)
    c_a = 0.5 * a * dt**2 * np.sinc(th / (2.0 * np.pi)) ** 2
    T = np.zeros((*a.shape, 4, 4))
    T[..., 0, 0] = T[..., 1, 1] = 1.0
    T[..., 0, 2], T[..., 0, 3], T[..., 1, 2], T[..., 1, 3] = s_a, c_a, -c_a, s_a
    T[..., 2, 2], T[..., 2, 3], T[..., 3, 2], T[..., 3, 3] = c, s, -s, c
    return T


def turn_rates(settings: DataSettings, streams: list[np.random.Generator], K: int) -> np.ndarray:
    """The turn rate of every transition (B, K + 1), ``a[:, k]`` taking sample ``k − 1`` to ``k``
    (``a[:, 0]`` unused, 0): module docstring. Each run draws ``turn_steps`` normals per segment,
    in segment order, whatever ``K`` (a short run keeps the draws of a long one)."""
    m, dt = settings.model, float(settings.sample_period)
    L, mean = int(m.turn_steps), float(m.turn_angle) / int(m.turn_steps) / dt
    a = np.zeros((len(streams), K + 1 + max(int(s) for s in m.turn_starts) + L))
    for b, rng in enumerate(streams):
        draws = rng.standard_normal((len(m.turn_starts), L))
        for start, row in zip(m.turn_starts, draws, strict=True):
            a[b, int(start) : int(start) + L] = mean + float(m.turn_rate_std) * row
    return a[:, : K + 1]


def simulate_truth(x0: np.ndarray, a: np.ndarray, dt: float) -> np.ndarray:
    """The target's states (B, K + 1, 4) from ``x0`` (4,) through the turn rates ``a`` (B, K + 1)."""
    T = turn_transition(a, dt)
    x = np.empty((*a.shape, 4))
    x[:, 0] = x0
    for k in range(1, a.shape[1]):
        x[:, k] = np.einsum("bij,bj->bi", T[:, k], x[:, k - 1])
    return x


def validate_bearings_only(settings: DataSettings) -> None:
    """Range checks of ``model=bearings_only``."""
    m = settings.model
    require_positive("model.bearing_std", m.bearing_std, "must be > 0 (bearing noise standard deviation, rad)")
    require_positive("model.q", m.q, "must be > 0 (spectral density of the filters' Wiener velocity model)")
    if len(list(m.sensor_x)) != len(list(m.sensor_y)) or not list(m.sensor_x):
        raise ConfigError("model.sensor_y", list(m.sensor_y), "as many values as model.sensor_x (at least one)")
    for key in ("m0", "P0", "x0"):
        if len(list(getattr(m, key))) != 4:
            raise ConfigError(f"model.{key}", list(getattr(m, key)), "four values: x, y, vx, vy")
    for value in m.P0:
        require_positive("model.P0", value, "must be > 0 (initial variances of the filters)")
    require_positive("model.turn_steps", m.turn_steps, "must be > 0 (steps of each turn)")
    if any(int(s) < 1 for s in m.turn_starts):
        raise ConfigError("model.turn_starts", list(m.turn_starts), "steps >= 1 (step 1 is the first transition)")
    if float(m.turn_rate_std) < 0:
        raise ConfigError("model.turn_rate_std", m.turn_rate_std, "must be >= 0")


def build_bearings_only_data(settings: DataSettings) -> MonteCarloData:
    """Truth and bearings of ``settings.runs`` runs (module docstring); every filter starts from
    ``m0``, ``diag(P0)``. Sample 0 is the known start: its bearings are drawn but never used."""
    m, runs, seed = settings.model, int(settings.runs), int(settings.seed)
    dt, K = float(settings.sample_period), sample_count(settings.duration, settings.sample_period)
    sensors = np.column_stack([np.array(list(m.sensor_x), dtype=float), np.array(list(m.sensor_y), dtype=float)])
    model = BearingsOnlyModel(dt, float(m.q), float(m.bearing_std), sensors, runs)
    streams = run_streams(seed, runs, settings.first_run)
    x = simulate_truth(np.array(list(m.x0), dtype=float), turn_rates(settings, streams["process"], K), dt)
    noise = np.stack([rng.standard_normal((K + 1, model.m)) for rng in streams["measurement"]])
    z = model.h(x, np.zeros((runs, 0))) + float(m.bearing_std) * noise
    x0_est = np.broadcast_to(np.array(list(m.m0), dtype=float), (runs, 4)).copy()
    return MonteCarloData(
        model, np.arange(K + 1) * dt, x, np.zeros((runs, K + 1, 0)), np.zeros((runs, K + 1, 0)), z, x0_est,
        np.diag(np.array(list(m.P0), dtype=float)), np.zeros((runs, 0)),
        run_seed_sequences(seed, runs, settings.first_run)["estimator"], simulation_labels(settings),
    )  # fmt: skip


MODEL = ModelSpec(  # the truth turns without process noise, not the filters' Wiener velocity model: no bound
    "bearings_only",
    BearingsOnlyModelConf,
    build_bearings_only_data,
    lambda _: 4,
    validate_bearings_only,
    job_defaults={"duration": 5.0, "sample_period": 0.01},  # the manual's 500 steps of 0.01 (§3.6)
)
