"""The open-loop job kind (``loop: open``, no ``source``): simulated Monte Carlo data, every
estimator on the same data, errors against its truth (``docs/outputs.md``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from quadest.app.estimator_runs import OnData
from quadest.app.pipeline import Finished, Report, TableRows
from quadest.app.settings import JobSettings
from quadest.evaluation.captions import table_caption
from quadest.evaluation.job_tables import MetricTables, metric_tables
from quadest.evaluation.metrics import convergence_table
from quadest.evaluation.pcrlb import pcrlb_variances
from quadest.evaluation.plotting import (
    plot_consistency,
    plot_errors,
    plot_extra_figures,
    plot_rmse_vs_time,
    plot_truth_vs_estimate,
)
from quadest.montecarlo import MonteCarloData
from quadest.montecarlo.results import EstimatorResult
from quadest.simulation.registry import build_data


class OpenLoopJob:
    """:class:`~quadest.app.pipeline.JobKind` of the open loop: the data builder gets the job's
    :class:`~quadest.config.settings.DataSettings`, the report reads the typed experiment."""

    caches_data = True

    def __init__(self, settings: JobSettings) -> None:
        self.settings, self.experiment = settings, settings.experiment

    def make_data(self) -> MonteCarloData:
        return build_data(self.settings.data)

    def work(self, data: MonteCarloData) -> OnData:
        return OnData(data)

    def report(self, finished: Finished) -> Report:
        cfg, data, out_dir = self.experiment, finished.data, finished.out_dir
        results = finished.rows.results
        bound = finished.derived("pcrlb", lambda: pcrlb_variances(data))
        tables = self.tables(data, finished.rows, bound)
        if data.model.bias_states:
            convergence_table(results, data).to_csv(out_dir / "convergence.csv", index=False)
        arrays = {}
        if finished.saved_runs:
            arrays = series(data, results, finished.saved_runs)
            if cfg.output.figures:
                self._figures(data, results, arrays, bound, out_dir / "figures")
        fields = {
            "labels": {**data.labels, "seed": int(cfg.seed), "runs": int(cfg.runs),
                       "duration": float(cfg.duration), "sample_period": float(cfg.sample_period)},
            "state_names": list(data.model.state_names),
            "error_names": list(data.model.error_names),
            "companion_names": list(data.model.companion_names),
            "measurement_names": list(data.model.measurement_names),
        }  # fmt: skip
        head = (f"Per-state RMSE, mean ± std over {int(cfg.runs)} Monte Carlo runs (per-run RMSE over time; diverged "
                "runs excluded).")  # fmt: skip
        caption = table_caption(head, self.settings.data.model.name, results, labels=data.labels)
        return Report(tables, fields, arrays, caption)

    def tables(self, data: MonteCarloData, rows: TableRows, bound: np.ndarray) -> MetricTables:
        """The metric tables of ``rows`` (:func:`~quadest.app.pipeline.table_rows` of the results on
        ``data``), labelled with the seed and the runs; ``bound`` the PCRLB
        (:func:`~quadest.evaluation.pcrlb.pcrlb_variances` of ``data``)."""
        cfg = self.experiment
        labels = {"seed": int(cfg.seed), "runs": int(cfg.runs)}
        return metric_tables(rows.results, data, rows.params, labels, bound, cfg.metrics)

    def _figures(
        self, data: MonteCarloData, results: list[EstimatorResult], arrays: dict, bound: np.ndarray, fig_dir: Path
    ) -> None:
        fig_dir.mkdir(exist_ok=True)
        ran = [r for r in results if r.saved["estimate"].shape[0]]
        if not ran:  # every estimator failed to build: the failures are in summary.json, there is nothing to plot
            return
        plot_truth_vs_estimate(data, ran, fig_dir / "truth_vs_estimate.png")
        if self.experiment.output.per_estimator_figures:
            for res in ran:
                plot_truth_vs_estimate(data, [res], fig_dir / f"truth_vs_estimate_{res.name}.png")
        plot_errors(data, ran, fig_dir / "errors_3sigma.png", bound)
        plot_rmse_vs_time(data, results, bound, fig_dir / "rmse_vs_time.png")
        plot_consistency(data, results, fig_dir / "consistency.png")
        plot_extra_figures(data.model, arrays, fig_dir)


def series(data: MonteCarloData, results: list[EstimatorResult], saved_runs: int) -> dict[str, np.ndarray]:
    """``timeseries.npz`` of an open-loop job: time, the truth of the first runs and each
    estimator's saved series."""
    arrays = {"time": data.time, "truth": data.truth[:saved_runs], "companion_truth": data.companion_truth[:saved_runs]}
    for res in results:
        for key, value in res.saved.items():
            arrays[f"{res.name}/{key}"] = value
    return arrays
