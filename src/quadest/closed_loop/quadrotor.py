"""The closed loop of ``model=quadrotor``: the plant's draws, the controller, the references, and
the three ways of flying it.

- ``truth`` and ``measured``: the flight does not depend on any estimator, so it is flown once
  and measured exactly as the open loop measures its truth
  (:func:`~quadest.simulation.quadrotor_data.record_quadrotor_data`); every estimator then runs on the
  same data. With ``truth`` the flight is the open loop's, bit for bit.
- ``estimate``: each estimator flies its own plant, stepped together with it (all runs of one
  estimator and its plants as one batch), from the same draws as every other estimator.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import ClassVar

import numpy as np

from quadest.closed_loop.control_metrics import StepEvent, control_metrics, step_events
from quadest.closed_loop.feedback import EstimateFeedback, StateSensorFeedback, TruthFeedback
from quadest.closed_loop.loop import CrashLimits, Flight, FlightRecord, fly
from quadest.config.settings import DataSettings
from quadest.estimators.base import Estimator
from quadest.models.quadrotor import QuadrotorFilterModel
from quadest.models.quadrotor_config import controller_gains, quadrotor_params, scenario
from quadest.montecarlo import MonteCarloData
from quadest.montecarlo.data import sample_count
from quadest.montecarlo.results import EstimatorResult
from quadest.montecarlo.streams import run_seed_sequences, run_streams
from quadest.quadrotor.controller import BacksteppingController
from quadest.quadrotor.plant import PlantDraws, QuadrotorPlant
from quadest.quadrotor.scenarios import AttitudeSteps, Reference, Scenario
from quadest.runner import EstimatorTracker, FilterStart
from quadest.simulation.quadrotor_data import MODEL as QUADROTOR_MODEL
from quadest.simulation.quadrotor_data import (
    data_labels,
    draw_plant,
    initial_condition,
    quadrotor_filter_model,
    record_quadrotor_data,
)


@dataclass
class QuadrotorLoop:
    """Everything a closed-loop job of ``model=quadrotor`` flies with, built once from the job's
    typed :class:`~quadest.config.settings.DataSettings` (the loop flies the model, sensors,
    scenario and closed-loop settings of the data, and records what the data builders record)."""

    model_name: ClassVar[str] = QUADROTOR_MODEL.name
    """The ``model`` option this loop flies (:func:`quadest.closed_loop.loops.closed_loop_for`)."""

    settings: DataSettings
    flown: Scenario
    draws: PlantDraws
    controller: BacksteppingController
    references: list[Reference]
    limits: CrashLimits
    state_std: np.ndarray
    events: list[StepEvent]
    band: float
    steady_window: float
    transient_window: float | None

    @classmethod
    def from_settings(cls, settings: DataSettings) -> QuadrotorLoop:
        loop = settings.closed_loop
        T = float(settings.sample_period)
        flown = scenario(settings.scenario)
        time = np.arange(sample_count(float(settings.duration), T) + 1) * T
        streams = run_streams(int(settings.seed), int(settings.runs))
        params = quadrotor_params(settings.model)
        return cls(
            settings=settings,
            flown=flown,
            draws=draw_plant(settings, streams, flown),
            controller=BacksteppingController(params, controller_gains(settings.model.controller)),
            references=[flown.reference(t) for t in time],
            limits=CrashLimits(loop.max_tilt, loop.ground_depth),
            state_std=loop.state_sensor.std(),
            events=step_events(flown.steps, float(settings.duration)) if isinstance(flown, AttitudeSteps) else [],
            band=loop.settling_band,
            steady_window=loop.steady_window,
            transient_window=loop.transient_window,
        )

    def plant(self) -> QuadrotorPlant:
        """A fresh batch of plants at sample 0, from the runs' draws."""
        c = self.settings
        return QuadrotorPlant(
            self.controller.params, self.draws, float(c.sample_period), int(c.model.truth_substeps),
            int(c.sensor.encoder.lines),
        )  # fmt: skip

    def reference_array(self) -> np.ndarray:
        """(K+1, 16) the references laid out as the truth (position and Euler-angle slots)."""
        out = np.zeros((len(self.references), 16))
        for k, ref in enumerate(self.references):
            out[k, 0:3], out[k, 6:9] = ref.position, ref.attitude
        return out

    def metrics(self, flight: Flight) -> dict[str, np.ndarray]:
        """Per-run control metrics of ``flight``; NaN for crashed runs."""
        tr = flight.truth
        out = control_metrics(
            tr.time, tr.state, self.reference_array(), tr.command, self.controller.params.hover_speed,
            self.references[-1].attitude_mode, self.events, self.band, self.steady_window, self.transient_window,
        )  # fmt: skip
        return {key: np.where(flight.crashed, np.nan, value) for key, value in out.items()}

    def flight_record(self, flight: Flight, runs: int | None = None) -> FlightRecord:
        """What a job keeps of ``flight``: its crashes, the control metrics of every run
        (:meth:`metrics`) and the truth and commands of the first ``runs`` runs (all: ``None``)."""
        return FlightRecord(
            flight.crash_step.copy(), dict(flight.crash_reasons), self.metrics(flight),
            flight.truth.state[:runs].copy(), flight.truth.command[:runs].copy(),
        )  # fmt: skip

    def fly_shared(self, loop: str) -> tuple[Flight, MonteCarloData]:
        """``loop`` = ``truth`` or ``measured``: fly once and measure the flight as the open loop
        measures its truth (fresh streams, the same draws)."""
        flight = fly(self.plant(), self.controller, self.references, self.shared_feedback(loop), self.limits)
        return flight, self.record(flight)

    def shared_feedback(self, loop: str) -> TruthFeedback | StateSensorFeedback:
        """What the controller reads with ``loop`` = ``truth`` or ``measured``."""
        return TruthFeedback() if loop == "truth" else StateSensorFeedback(self.state_std)

    def estimate_feedback(self, tracker: EstimatorTracker, plant: QuadrotorPlant) -> EstimateFeedback:
        """What the controller reads with ``loop: estimate``."""
        return EstimateFeedback(tracker, plant)

    def record(self, flight: Flight) -> MonteCarloData:
        """What the filters see of a shared flight: the open loop's measurements of its truth."""
        return record_quadrotor_data(self.settings, self._streams(), self.flown, flight.truth)

    def filter_model(self) -> QuadrotorFilterModel:
        """The filter model of the job, bound to the runs' assumed sensor errors."""
        return quadrotor_filter_model(self.settings, self.draws.accel_errors, self.draws.gyro_errors)

    def _flight_data(self, model: QuadrotorFilterModel, states: np.ndarray) -> MonteCarloData:
        """The data of one estimator's flight of 16-states ``states`` (B, K+1, 16): truth and
        companion truth; the inputs and measurements were consumed in the loop and are not kept."""
        s = self.settings
        B, K1 = states.shape[:2]
        x0, P0 = initial_condition(s, model.state_names, model.truth_to_state(states[:, 0]), self._streams())
        return MonteCarloData(
            model=model, time=np.arange(K1) * float(s.sample_period), truth=model.truth_to_state(states),
            companion_truth=model.truth_to_companion(states), inputs=np.empty((B, K1, 0)),
            measurements=np.empty((B, K1, 0)), x0=x0, P0=P0, companion0=model.truth_to_companion(states[:, 0]),
            estimator_seeds=run_seed_sequences(int(s.seed), B)["estimator"], labels=data_labels(s, self.flown),
        )  # fmt: skip

    def _streams(self) -> dict:
        return run_streams(int(self.settings.seed), int(self.settings.runs))

    def empty_data(self, model: QuadrotorFilterModel) -> MonteCarloData:
        """The data of an estimator that could not fly: its truth after sample 0 is NaN."""
        plant = self.plant()
        states = np.full((plant.state.shape[0], len(self.references), 16), np.nan)
        states[:, 0] = plant.state
        return self._flight_data(model, states)

    def fly_estimator(
        self, name: str, est: Estimator, bound: float, saved_runs: int
    ) -> tuple[EstimatorResult, Flight, MonteCarloData]:
        """``loop: estimate``: ``est`` (built on :meth:`filter_model`) flies its own plants, from the
        same draws as every other estimator. Returns its result (scored against its own truth,
        which it carries), its flight, and the data of its flight."""
        plant = self.plant()
        model = est.model
        start_data = self._flight_data(model, plant.state[:, None])
        tracker = EstimatorTracker(
            name, est, model, FilterStart.of(start_data), len(self.references) - 1, bound, saved_runs
        )
        flight = fly(plant, self.controller, self.references, self.estimate_feedback(tracker, plant), self.limits)
        data = self._flight_data(model, flight.truth.state)
        own = replace(
            tracker.result(), truth=data.truth[:saved_runs], companion_truth=data.companion_truth[:saved_runs]
        )
        return own, flight, data
