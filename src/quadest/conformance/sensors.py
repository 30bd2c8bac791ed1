"""Conformance checks for sensor plugins (``docs/sensors.md``): :func:`check_sensor`.

A sensor is checked where every quantity but a moving platform's position is offered: on the
INS (``model=ins``, :func:`quadest.models.ins.ins_layout`), whose truth the sensor measures as in
a job (:class:`~quadest.sensors.base.TrueMotion` of the INS's simulated flight).

1. the class meets the contract (:func:`~quadest.sensors.base.sensor_problems`) and its own
   checks accept ``settings``;
2. its samples: ``values`` (B, K+1, m) with ``m`` the length of its model's ``names``,
   ``available`` a (K+1,) bool mask, finite values wherever a sample is available, and, when the
   settings have a ``rate``, no sample off that rate's grid
   (:func:`~quadest.sensors.base.available_samples`);
3. stream isolation: it draws only from the streams it is handed (``sensor:<name>:<stream>``, one
   generator per run, as :func:`quadest.simulation.aiding.measure_aiding` hands them): numpy's
   global generator is untouched, two simulations from the same seed are identical, another
   seed changes the samples, and run ``i`` of a batch gets the samples it gets alone from its own
   generator (where both are available: a mask may depend on the whole batch);
4. its filters' model, asked of the instance that simulated (it may keep a calibration):
   ``h`` (B, K, m), ``R`` (m, m) symmetric with a positive diagonal, and the analytic
   ``jacobian`` (B, m, n_err) on the error state equal to central differences of ``h`` on the
   INS's manifold (:meth:`quadest.models.base.FilterModel.manifold_jacobian_fd`, points
   ``x ⊞ (±h e_j)``) at true states along the flight.

Each failure raises ``AssertionError`` naming the sensor and the first check that fails.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from quadest.conformance.compose import compose_settings
from quadest.conformance.jacobians import assert_jacobian
from quadest.models.ins import ATT, POS, VEL, ins_layout
from quadest.montecarlo.data import MonteCarloData
from quadest.montecarlo.streams import named_streams
from quadest.sensors.base import Sensor, StateLayout, TrueMotion, available_samples, sensor_problems
from quadest.sensors.record import SensorRecord
from quadest.simulation.aiding import sensor_context
from quadest.simulation.registry import build_data

__all__ = ["check_sensor"]


def _streams(cls: type[Sensor], seed: int, runs: int, first_run: int = 0) -> dict[str, list[np.random.Generator]]:
    return {s: named_streams(seed, runs, f"sensor:{cls.config_name}:{s}", first_run) for s in cls.stream_names()}


def _motion(data: MonteCarloData, runs: slice = slice(None)) -> TrueMotion:
    x = data.truth[runs]
    return TrueMotion(data.time, x[..., POS], x[..., VEL], x[..., ATT])


def _simulate(sensor: Sensor, motion: TrueMotion, streams) -> SensorRecord:
    record = sensor.simulate(motion, streams)
    return SensorRecord(np.asarray(record.values, dtype=float), np.asarray(record.available))


def check_sensor(
    cls: type[Sensor],
    settings: Any = None,
    overrides: Sequence[str] = (),
    runs: int = 3,
    seed: int = 9,
) -> None:
    """Run the conformance checks on sensor class ``cls`` (see the module docstring).

    Args:
        cls: a subclass of :class:`~quadest.sensors.base.Sensor`; it need not be registered.
        settings: an instance of ``cls.Settings``; by default its defaults.
        overrides: further overrides of the INS job the sensor measures (``duration=5``,
            ``scenario=...``), as on the command line.
        runs: Monte Carlo runs of the batch.
        seed: the job's seed.
    """
    name = getattr(cls, "__name__", repr(cls))
    problems = sensor_problems(cls)
    assert not problems, f"{name}: contract: {'; '.join(problems)}"
    settings = cls.Settings() if settings is None else settings
    job = compose_settings(["model=ins", "model.aiding=[]", f"runs={runs}", f"seed={seed}", "duration=3", *overrides])
    cls.validate(settings, cls.key(), float(job.sample_period))
    data = build_data(job)
    context = sensor_context(job, job.model.calibrated, job.model.measurement_noise_inflation)
    motion = _motion(data)
    K1 = data.time.size

    state = np.random.get_state()
    sensor = cls(settings, context)
    record = _simulate(sensor, motion, _streams(cls, seed, runs))
    after = np.random.get_state()
    assert after[0] == state[0] and np.array_equal(after[1], state[1]) and after[2:] == state[2:], (
        f"{name}: simulate drew from numpy's global generator; draw from the streams it is handed"
    )
    model = sensor.measurement_model(ins_layout())  # after simulate, on the same instance (a calibration)
    m = len(model.names)
    values, available = record.values, record.available
    assert values.shape == (runs, K1, m), f"{name}: values have shape {values.shape}, expected {(runs, K1, m)}"
    assert available.shape == (K1,) and available.dtype == bool, (
        f"{name}: available must be a ({K1},) bool mask, got {available.dtype} {available.shape}"
    )
    assert available.any(), f"{name}: no sample available in {K1} steps"
    assert np.isfinite(values[:, available]).all(), f"{name}: a value is not finite where a sample is available"
    if hasattr(settings, "rate"):
        grid = available_samples(float(settings.rate), float(job.sample_period), K1, f"{cls.key()}.rate")
        assert not (available & ~grid).any(), f"{name}: a sample off the grid of rate={settings.rate} Hz"

    _check_streams(name, cls, settings, context, data, record, seed)
    _check_model(name, model, ins_layout(), data, m)


def _check_streams(name: str, cls, settings, context, data: MonteCarloData, record: SensorRecord, seed: int) -> None:
    runs = data.truth.shape[0]
    motion = _motion(data)
    again = _simulate(cls(settings, context), motion, _streams(cls, seed, runs))
    assert np.array_equal(again.values, record.values, equal_nan=True), (
        f"{name}: two simulations from the same streams differ (a draw from a generator it was not handed)"
    )
    other = _simulate(cls(settings, context), motion, _streams(cls, seed + 1, runs))
    assert not np.array_equal(other.values, record.values, equal_nan=True), (
        f"{name}: another seed gives the same samples: its noise does not come from its streams"
    )
    for i in range(runs):
        alone = _simulate(cls(settings, context), _motion(data, slice(i, i + 1)), _streams(cls, seed, 1, first_run=i))
        both = record.available & alone.available
        assert np.array_equal(alone.values[0, both], record.values[i, both]), (
            f"{name}: run {i} in a batch differs from run {i} alone: each run draws from its own generator"
        )


def _check_model(name: str, model, layout: StateLayout, data: MonteCarloData, m: int) -> None:
    filter_model = data.model
    R = np.asarray(model.R)
    assert R.shape == (m, m), f"{name}: R has shape {R.shape}, expected {(m, m)}"
    assert np.allclose(R, R.T, rtol=1e-12, atol=0) and (np.diag(R) > 0).all(), (
        f"{name}: R must be symmetric with a positive diagonal"
    )
    K = data.time.size - 1
    for k in (1, K // 2, K):
        x, u = data.truth[:, k], data.inputs[:, k]
        y = model.h(x[:, None], u)
        assert y.shape == (x.shape[0], 1, m), f"{name}: h has shape {y.shape}, expected {(x.shape[0], 1, m)}"
        J = np.asarray(model.jacobian(x, u))
        assert J.shape == (x.shape[0], m, layout.n_err), (
            f"{name}: jacobian has shape {J.shape}, expected {(x.shape[0], m, layout.n_err)}"
        )
        J_fd = filter_model.manifold_jacobian_fd(model.h, x, u, state_valued=False)
        assert_jacobian(f"{name}: jacobian at step {k}", J, J_fd, y, filter_model.fd_step)
