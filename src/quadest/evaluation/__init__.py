"""The evaluation layer: scoring estimator results and presenting them.

- :mod:`~quadest.evaluation.metrics`: RMSE, NEES, NIS and the per-run tables;
- :mod:`~quadest.evaluation.paired`: paired comparisons of estimators on the same runs;
- :mod:`~quadest.evaluation.pcrlb`: the posterior Cramér–Rao lower bound;
- :mod:`~quadest.evaluation.plotting`: a job's figures;
- :mod:`~quadest.evaluation.job_tables`: every job's tables;
- :mod:`~quadest.evaluation.formatting`: Markdown and LaTeX tables, strict JSON;
- :mod:`~quadest.evaluation.objective`: the number a tuning sweep minimises.

It reads :class:`~quadest.montecarlo.results.EstimatorResult` and never runs an estimator
(``docs/layout.md``).
"""
