"""The simulation layer: the Monte Carlo data of every ``model=`` option.

Each option's data builder flies or simulates the truth, measures it and draws the filters'
initial estimates (``*_data`` modules, one per model of :mod:`quadest.models`);
:mod:`~quadest.simulation.registry` names the options and picks simulated or replayed data
(:mod:`quadest.replay`). Estimators never import this layer: they see the filter model only.
"""
