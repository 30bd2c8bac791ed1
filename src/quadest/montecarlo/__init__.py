"""Monte Carlo data: one truth, input and measurement record per run, shared by every estimator.

- :mod:`quadest.montecarlo.data`: the container the runner consumes, :class:`MonteCarloData`;
- :mod:`quadest.montecarlo.streams`: the per-run random streams (common random numbers);
- :mod:`quadest.montecarlo.initial`: the filters' initial condition, P0 and x0 ~ N(truth, P0).

Each model's data builder (``quadest.models.quadrotor_data``, ``quadest.models.validation``)
fills a :class:`MonteCarloData` from these.
"""

from quadest.montecarlo.data import MonteCarloData

__all__ = ["MonteCarloData"]
