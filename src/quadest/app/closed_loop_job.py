"""The closed-loop job kind (``loop`` ≠ ``open``): fly, filter, score (``docs/closed-loop.md``).

The outputs are those of an open-loop job (``docs/outputs.md``), scored against each estimator's
own truth, plus the control tables (:mod:`quadest.closed_loop.control_tables`) and
``figures/tracking.png``.

- ``truth`` / ``measured``: the flight does not depend on any estimator. It is flown once, in
  :meth:`ClosedLoopJob.make_data`, and cached with the job's data (:class:`ClosedLoopData`);
  every estimator then runs on the recorded flight (:class:`~quadest.app.estimator_runs.OnData`),
  its crashed runs ending at the crash.
- ``estimate``: every estimator flies its own plants (:class:`OwnFlights`), and its result carries
  what the job keeps of that flight (:class:`~quadest.closed_loop.loop.FlightRecord`). Its cache
  key is the estimator key: the flight depends on the data key's settings (the loop, the draws,
  the controller, the scenario), the estimator's own node and the runner settings, and on no
  other estimator, so a cached flight is the one this job would fly. There are no shared data
  to cache (:attr:`ClosedLoopJob.caches_data` is false). The PCRLB (a bound along one truth) is
  left out: its column is empty and ``summary.json`` says why.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from quadest.app.estimator_runs import OnData, RunSettings, picklable
from quadest.app.pipeline import Finished, Report
from quadest.app.settings import JobSettings
from quadest.closed_loop.control_tables import control_entries, control_table, write_control_tables
from quadest.closed_loop.figures import plot_tracking
from quadest.closed_loop.loop import FlightRecord
from quadest.closed_loop.loops import closed_loop_for, controlled_models
from quadest.closed_loop.quadrotor import QuadrotorLoop
from quadest.config.closed_loop import validate_loop
from quadest.estimators.registry import build_estimator
from quadest.evaluation.captions import table_caption
from quadest.evaluation.job_tables import metric_tables
from quadest.evaluation.pcrlb import pcrlb_variances
from quadest.evaluation.plotting import plot_truth_vs_estimate
from quadest.montecarlo import MonteCarloData
from quadest.montecarlo.results import EstimatorResult, failed_result

PCRLB_NOTE = "left out with loop=estimate: each estimator flies its own truth, and the PCRLB is a bound along one truth"
FED = {
    "truth": "the true state",
    "measured": "noisy states (closed_loop.state_sensor)",
    "estimate": "each estimator's estimate; RMSE against each estimator's own truth",
}


@dataclass
class ClosedLoopData:
    """The data of a closed-loop job: what the filters see and are scored with, and, with ``truth``
    and ``measured``, the one flight every estimator watches (all its runs kept)."""

    data: MonteCarloData
    flight: FlightRecord | None


@dataclass
class OwnFlights:
    """``loop: estimate``: each estimator flies its own plants, from the same draws as every
    other estimator. An estimator that cannot be built, or raises in flight, has no flight; every
    run is flagged with the reason."""

    loop: QuadrotorLoop

    def run(self, label: str, node: dict, settings: RunSettings) -> EstimatorResult:
        est = build_estimator(label, node, self.loop.filter_model())
        result, flight, _ = self.loop.fly_estimator(label, est, settings.divergence_bound, settings.saved_runs)
        return replace(result, flight=self.loop.flight_record(flight, settings.saved_runs))

    def failed(self, label: str, reason: str, settings: RunSettings) -> EstimatorResult:
        data = self.loop.empty_data(self.loop.filter_model())
        saved = settings.saved_runs
        return replace(failed_result(label, data, reason), truth=data.truth[:saved],
                       companion_truth=data.companion_truth[:saved])  # fmt: skip

    def shippable(self) -> bool:
        """The loop is built from the job's typed settings (:class:`ClosedLoopJob`): it pickles."""
        return picklable(self.loop)


class ClosedLoopJob:
    """:class:`~quadest.app.pipeline.JobKind` of the closed loop (module docstring)."""

    def __init__(self, settings: JobSettings) -> None:
        exp = settings.experiment
        validate_loop(exp.loop, exp.model.name, exp.closed_loop, controlled_models())
        self.experiment, self.mode = exp, str(exp.loop)
        self.caches_data = self.mode != "estimate"
        # the loop goes to worker processes: its typed settings are module-level dataclasses, they pickle
        self.loop = closed_loop_for(settings.data)

    def make_data(self) -> ClosedLoopData:
        if self.mode == "estimate":  # no shared flight: the scaffold of every estimator's results
            return ClosedLoopData(self.loop.empty_data(self.loop.filter_model()), None)
        flight, data = self.loop.fly_shared(self.mode)
        return ClosedLoopData(data, self.loop.flight_record(flight))

    def work(self, data: ClosedLoopData) -> OnData | OwnFlights:
        if data.flight is None:
            return OwnFlights(self.loop)
        return OnData(data.data, crashes=(data.flight.crash_step, data.flight.crash_reasons))

    def report(self, finished: Finished) -> Report:
        cfg, mode, out_dir = self.experiment, self.mode, finished.out_dir
        data: MonteCarloData = finished.data.data
        runs, saved, results = int(cfg.runs), finished.saved_runs, finished.rows.results
        if finished.data.flight is None:
            flights = {res.name: res.flight for res in finished.results}
            pcrlb, pcrlb_note = np.full((data.time.size, data.model.n_err), np.nan), PCRLB_NOTE
        else:
            flights = {mode: finished.data.flight}
            pcrlb, pcrlb_note = finished.derived("pcrlb", lambda: pcrlb_variances(data)), None
        control_summary = write_control_tables(out_dir, control_table(flights, runs, mode))
        labels = {"seed": int(cfg.seed), "runs": runs, "loop": mode}
        tables = metric_tables(results, data, finished.rows.params, labels, pcrlb, cfg.metrics)
        arrays = {}
        if saved:
            arrays = self._series(data, flights, results, saved)
            if cfg.output.figures:
                self._figures(data, flights, results, saved, out_dir / "figures")
        fields = {
            "labels": {**data.labels, "seed": int(cfg.seed), "runs": runs, "duration": float(cfg.duration),
                       "sample_period": float(cfg.sample_period), "loop": mode},
            "state_names": list(data.model.state_names),
            "companion_names": list(data.model.companion_names),
            "measurement_names": list(data.model.measurement_names),
            "pcrlb_note": pcrlb_note,
            "control": control_entries(control_summary),
            "crashes": {name: int(f.crashed.sum()) for name, f in flights.items() if f is not None},
        }  # fmt: skip
        caption = table_caption(
            f"Per-state RMSE, mean ± std over {runs} Monte Carlo runs, loop={mode}: the controller flies on "
            f"{FED[mode]}.",
            cfg.model.name,
            results,
            None if pcrlb_note is None else f"PCRLB: {pcrlb_note}",
            [f"Control metrics: {out_dir / 'control_table.md'}"],
        )
        return Report(tables, fields, arrays, caption)

    def _series(
        self, data: MonteCarloData, flights: dict[str, FlightRecord | None], results: list[EstimatorResult], saved: int
    ) -> dict[str, np.ndarray]:
        """``timeseries.npz``: also the reference, every flight's truth and commands, and the truth
        each estimator was scored against."""
        arrays = {"time": data.time, "reference": self.loop.reference_array()}
        for name, flight in flights.items():
            if flight is not None:
                arrays[f"flight/{name}/truth"] = flight.state[:saved]
                arrays[f"flight/{name}/command"] = flight.command[:saved]
        for res in results:
            truth, companion = _own_truth(res, data, saved)
            arrays[f"{res.name}/truth"] = truth
            arrays[f"{res.name}/companion_truth"] = companion
            for key, value in res.saved.items():
                arrays[f"{res.name}/{key}"] = value
        return arrays

    def _figures(
        self,
        data: MonteCarloData,
        flights: dict[str, FlightRecord | None],
        results: list[EstimatorResult],
        saved: int,
        fig_dir: Path,
    ) -> None:
        fig_dir.mkdir(exist_ok=True)
        responses = {name: f.state[0] for name, f in flights.items() if f is not None}
        plot_tracking(data.time, self.loop.reference_array(), responses, self.loop.events, fig_dir / "tracking.png",
                      f"Tracking, run 0, loop={self.mode}")  # fmt: skip
        for res in results:
            if res.saved["estimate"].shape[0]:
                truth, companion = _own_truth(res, data, saved)
                view = replace(data, truth=truth, companion_truth=companion)
                plot_truth_vs_estimate(view, [res], fig_dir / f"truth_vs_estimate_{res.name}.png")


def _own_truth(res: EstimatorResult, data: MonteCarloData, saved: int) -> tuple[np.ndarray, np.ndarray]:
    """The truth (and companion truth) of the first ``saved`` runs that ``res`` was scored against:
    its own flight's, or the shared data's."""
    if res.truth is not None:
        return res.truth, res.companion_truth
    return data.truth[:saved], data.companion_truth[:saved]
