"""Smoothing behaviours a single-point bug breaks without any other test noticing.

- FFBSi (:func:`quadest.estimators.particle_smoothing.ffbsi`) weighs each backward step with the
  transition *into* the next step, evaluated with that transition's own input: checked on every
  registered model with additive state noise and an input, with inputs that change from step to
  step, against the exact law of the backward simulation enumerated in the test;
- every particle filter records, in its smoother cloud, the input of the transition into the
  step (the one ``predict`` received), not the input of the measurement.
"""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest

from helpers import compose_settings
from quadest.estimators.particle_smoothing import ParticleCloud, ffbsi
from quadest.estimators.registry import builtin_estimators, make_estimator
from quadest.simulation.registry import build_data, model_specs

RUNS, PARTICLES, STEPS, TRAJECTORIES = 2, 4, 4, 20000
Z = 4.5  # |error| / standard error bound per smoothed coordinate (two-sided 7e-6 each)


@cache
def model_data(name: str):
    """50 steps of every model (0.01 s each, whatever the model's own sample period)."""
    overrides = [f"model={name}", f"runs={RUNS}", "duration=0.5", "sample_period=0.01", "progress=false"]
    return build_data(compose_settings(overrides))


def additive_input_models() -> list[str]:
    """Registered models with an input and process noise on the state itself (what FFBSi assumes)."""
    names = []
    for name in sorted(model_specs()):
        model = model_data(name).model
        if model.nu > 0 and model.Q.shape == (model.n, model.n):
            names.append(name)
    return names


def backward_law(clouds: list[ParticleCloud], logpdf, f) -> list[np.ndarray]:
    """The marginal probabilities (B, N) of each particle of each step under Godsill, Doucet &
    West's backward simulation, enumerated: step K by the weights, step k from step k+1 by
    ``w_k^i N(x_{k+1}^j; f(x_k^i, u_{k+1}), Q)`` normalised over i."""
    law = [clouds[-1].weights]
    for k in range(len(clouds) - 2, -1, -1):
        B, N = clouds[k].particles.shape[:2]
        here, there = clouds[k], clouds[k + 1]
        prob = np.zeros((B, N))
        predicted = f(here.particles, there.input)  # (B, N, n)
        for b in range(B):
            kernel = np.array(
                [[here.weights[b, i] * np.exp(logpdf(there.particles[b, j] - predicted[b, i])) for i in range(N)]
                 for j in range(N)]
            )  # fmt: skip
            kernel /= kernel.sum(axis=1, keepdims=True)
            prob[b] = law[0][b] @ kernel
        law.insert(0, prob)
    return law


@pytest.mark.parametrize("name", additive_input_models())
def test_ffbsi_draws_each_backward_step_through_the_transition_into_the_next_step(name):
    """Clouds whose particles sit about one process-noise standard deviation apart around the
    model's predictions, with the inputs of widely separated steps (so consecutive inputs
    differ): the smoothed mean of each step is the mean under the enumerated backward law within
    Z standard errors of M draws (the standard error from the law's own variance)."""
    data = model_data(name)
    model = data.model
    rng = np.random.default_rng(5)
    picks = np.linspace(0, data.inputs.shape[1] - 1, STEPS).astype(int)[::-1]  # inputs far apart in time
    x = data.x0[:, None, :] + model.sample_process_noise(rng, (RUNS, PARTICLES))
    clouds = []
    for k in range(STEPS):
        u = model.filter_input(data.inputs[:, picks[k]], data.companion_truth[:, picks[k]])
        if k:
            x = model.f(x, u) + model.sample_process_noise(rng, (RUNS, PARTICLES))
        w = rng.uniform(0.2, 1.0, (RUNS, PARTICLES))
        clouds.append(ParticleCloud(x.copy(), w / w.sum(axis=1, keepdims=True), u.copy()))
    means, _ = ffbsi(clouds, model, [np.random.default_rng(s) for s in range(RUNS)], TRAJECTORIES)
    for k, prob in enumerate(backward_law(clouds, model.process_noise_logpdf, model.f)):
        expected = np.einsum("bi,bin->bn", prob, clouds[k].particles)
        second = np.einsum("bi,bin->bn", prob, clouds[k].particles ** 2)
        se = np.sqrt(np.maximum(second - expected**2, 0.0) / TRAJECTORIES)
        assert np.all(np.abs(means[k] - expected) <= Z * se + 1e-12 * np.abs(expected)), (k, means[k], expected, se)


PARTICLE_SMOOTHERS = sorted(
    name for name, spec in builtin_estimators().items() if "particle_smoothing" in spec.cls.capabilities
)


@pytest.mark.parametrize("name", PARTICLE_SMOOTHERS)
def test_every_particle_filter_keeps_the_input_of_the_transition_into_its_cloud(name):
    """``predict(u_{k-1})`` then ``update(z_k, u_k)`` with different inputs: the cloud of step k
    carries ``u_{k-1}``, the input FFBSi must use to reach step k from step k−1."""
    data = model_data("ungm")
    spec = builtin_estimators()[name]
    est = make_estimator(spec.cls, data.model, {"particles": 50})
    est.smoothing = True
    est.set_generators([np.random.default_rng(s) for s in range(RUNS)])
    est.initialize(data.x0, np.broadcast_to(data.P0, (RUNS, *data.P0.shape[-2:])).copy())
    for k in range(1, 4):
        est.predict(data.inputs[:, k - 1])
        est.update(data.measurements[:, k], data.inputs[:, k])
        assert not np.array_equal(data.inputs[:, k - 1], data.inputs[:, k])
        np.testing.assert_array_equal(est.smoother_cloud.input, data.inputs[:, k - 1])
