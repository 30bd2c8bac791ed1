"""Aggregate a sweep folder into tables, figures and a report: ``quadest-aggregate SWEEP_DIR``.

Also run automatically at the end of a multirun by
:class:`~quadest.app.callbacks.AggregateCallback`. It reads what each job documented
(``summary.json``, ``rmse_summary.csv``, ``.hydra/overrides.yaml``) and never needs a job to have
succeeded: failed jobs (``"status": "failed"``), jobs that never finished (no ``summary.json``)
and jobs that are missing from the grid are listed, and the rest is aggregated. It can be re-run
on any sweep folder (after SLURM, after a crash).

Writes into ``SWEEP_DIR/aggregate/``:

- ``cells.csv``: the tidy table, one row per job × estimator × state with the swept parameters
  and the group choices (``choice.sensor``, ...) as columns, the per-run RMSE mean, std and
  95 % confidence interval of the mean (Student t),
  the mean per-run MSE, pooled RMSE, PCRLB, diverged runs, NEES/NIS and time per step;
- ``rmse`` (per cell, estimator and state: ``mean ± std [95 % CI]``), ``best_cells``,
  ``divergence`` and ``timing`` tables as ``.csv``, ``.md`` and ``.tex``;
- ``jobs.csv``: every expected job and its status;
- ``figures/*.png`` and ``*.pdf``: RMSE vs α with one line per (β, κ); α × β heatmaps per state
  group; RMSE vs sensor error scale per estimator with 95 % error bars; a per-state RMSE bar chart;
- ``report.md``: all of the above, the commit and the sweep's overrides.

With ``output: compact`` under the callback (``quadest-aggregate SWEEP_DIR --output compact``) it
writes instead the compact aggregate of a large grid, one row per cell
(:mod:`~quadest.aggregate.compact`).

One module per job: :mod:`~quadest.aggregate.sweep` reads the folder,
:mod:`~quadest.aggregate.statistics` computes the confidence intervals and tables,
:mod:`~quadest.aggregate.figures` draws, :mod:`~quadest.aggregate.versus_best` compares each cell
with the best, :mod:`~quadest.aggregate.compact` writes the compact aggregate,
:mod:`~quadest.aggregate.report` writes everything,
:class:`~quadest.app.callbacks.AggregateCallback` and :mod:`~quadest.aggregate.cli` are the two ways in. The
Markdown and LaTeX rendering is shared with the job (:mod:`quadest.evaluation.formatting`).
"""
