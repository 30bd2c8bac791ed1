"""Monte Carlo data: one truth, input and measurement record per run, shared by every estimator.

- :mod:`quadest.montecarlo.data`: the container the runner consumes, :class:`MonteCarloData`;
- :mod:`quadest.montecarlo.streams`: the per-run random streams (common random numbers);
- :mod:`quadest.montecarlo.initial`: the filters' initial condition, P0 and x0 ~ N(truth, P0);
- :mod:`quadest.montecarlo.results`: what an estimator achieved on the data,
  :class:`~quadest.montecarlo.results.EstimatorResult`.

Each model's data builder (:mod:`quadest.simulation`, e.g. ``quadest.simulation.quadrotor_data``)
and the flight-log replay (:mod:`quadest.replay.data`) fill a :class:`MonteCarloData` from these.
"""

from quadest.montecarlo.data import MonteCarloData

__all__ = ["MonteCarloData"]
