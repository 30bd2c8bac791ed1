"""The application layer: what a user runs and what composes every feature.

- :mod:`~quadest.app.cli`: the ``quadest`` command (a Hydra app);
- :mod:`~quadest.app.job`: one job: build the data, run the estimators, write the outputs;
- :mod:`~quadest.app.schema`: the structured-config schemas, assembled from each feature's own;
- :mod:`~quadest.app.validate`: the range checks across features, run before any work starts;
- :mod:`~quadest.app.replay_report`: the outputs of a flight-log replay.

The other application packages sit beside it: :mod:`quadest.cache`, :mod:`quadest.closed_loop`
and :mod:`quadest.aggregate`. Nothing below this layer imports it (``docs/layout.md``).
"""
