"""Content-addressed cache of Monte Carlo data and estimator results (``docs/cache.md``).

:mod:`~quadest.cache.keys` says what a value depends on, :mod:`~quadest.cache.store` keeps the
files, :mod:`~quadest.cache.location` finds the folder, :mod:`~quadest.cache.lookup` is what a
job uses, and :mod:`~quadest.cache.cli` is the ``quadest-cache info|clear`` command.
"""
