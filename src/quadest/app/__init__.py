"""The application layer: what a user runs and what composes every feature.

- :mod:`~quadest.app.cli`: the ``quadest`` command (a Hydra app);
- :mod:`~quadest.app.job`: one job: validate, pick the job kind, run the pipeline;
- :mod:`~quadest.app.pipeline`: the one job pipeline: data, estimators, tables, ``timeseries.npz``
  and ``summary.json`` for every job kind;
- :mod:`~quadest.app.estimator_runs`: running the estimators: the result cache, the worker
  processes, failure isolation;
- :mod:`~quadest.app.open_loop_job`, :mod:`~quadest.app.closed_loop_job`,
  :mod:`~quadest.app.replay_job`: the job kinds (what differs between them);
- :mod:`~quadest.app.provenance`: the commit and code version in ``summary.json``;
- :mod:`~quadest.app.schema`: the structured-config schemas, assembled from each feature's own;
- :mod:`~quadest.app.validate`: the range checks across features, run before any work starts.

The other application packages sit beside it: :mod:`quadest.cache`, :mod:`quadest.closed_loop`
and :mod:`quadest.aggregate`. Nothing below this layer imports it (``docs/layout.md``).
"""
