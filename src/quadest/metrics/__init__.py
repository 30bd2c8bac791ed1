"""Metrics as parts (docs/metrics.md): what a metric is (:mod:`~quadest.metrics.base`), the
built-in ones (:mod:`~quadest.metrics.builtin`: RMSE, divergence, NEES, NIS, time per step,
diagnostics), the χ² bands (:mod:`~quadest.metrics.consistency`), credibility
(:mod:`~quadest.metrics.credibility`), NEES per state group and NIS per measurement group
(:mod:`~quadest.metrics.groups`), error quantiles (:mod:`~quadest.metrics.quantiles`), transient
and steady state (:mod:`~quadest.metrics.windows`), and the registry
(:mod:`~quadest.metrics.registry`).

The runner streams every step into the metrics' accumulators; the evaluation layer builds every
job's tables from their declared columns."""
