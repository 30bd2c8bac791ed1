"""The settings a job's data is made from, typed: :class:`DataSettings`.

The application layer composes the config with Hydra, validates it and converts it once
(:func:`quadest.app.settings.job_settings`); below it no module sees the raw config. The data
builders of every model option (:attr:`quadest.simulation.spec.ModelSpec.build`, its ``validate``
and ``state_dimension``), the closed loop (:mod:`quadest.closed_loop`) and the flight-log replay
(:mod:`quadest.replay.data`) take a :class:`DataSettings`; the other layers get their own node only
(the cache :class:`~quadest.app.schema.CacheConf`, the tuning objective
:class:`~quadest.app.schema.ObjectiveConf`, an estimator its resolved node as a plain dict).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from quadest.config.closed_loop import ClosedLoopConf


@dataclass
class DataSettings:
    """What a job's data depends on: the Monte Carlo settings and the typed ``model``, ``sensor``,
    ``scenario``, ``loop``, ``closed_loop`` and ``source`` nodes, plus the settings of each further
    sensor of ``model.aiding``.

    A data builder reads most of the experiment (runs and seed, timing, model, sensors, scenario),
    so it gets this one object rather than one node each; the estimators, the outputs, the cache
    and the objective are not in it. Every node is an instance of its schema dataclass.

    Attributes:
        runs, seed, duration, sample_period: the root's Monte Carlo settings.
        model: the ``model`` node, an instance of the option's ``ModelSpec.schema``.
        sensor: the ``sensor`` node, a :class:`quadest.app.schema.SensorConf` (MIMU, encoders and
            the built-in navigation sensors; a plugin sensor's settings are in ``aiding``).
        scenario: the ``scenario`` node, an instance of its class in
            :func:`quadest.quadrotor.scenario_registry.scenario_classes` (a model that flies no quadrotor ignores it).
        loop: ``open``, ``truth``, ``measured`` or ``estimate`` (docs/closed-loop.md).
        closed_loop: the closed loop's settings.
        source: the ``source`` node (:class:`quadest.app.schema.SourceConf`), ``None`` to simulate.
        aiding: each sensor of ``model.aiding`` (registered ones) → an instance of its ``Settings``
            from its settings node (``sensor.<name>`` or its ``settings_key``), ``None`` if the
            config has no such node.
        first_run: the index of the first run: the data of runs ``first_run .. first_run + runs − 1``,
            each from its own streams (:func:`quadest.montecarlo.streams.run_streams`), so the
            batches of a ``runs=auto`` job are the runs of one long job (0 for every other job).
    """

    runs: int
    seed: int
    duration: float
    sample_period: float
    model: Any
    sensor: Any = None
    scenario: Any = None
    loop: str = "open"
    closed_loop: ClosedLoopConf = field(default_factory=ClosedLoopConf)
    source: Any = None
    aiding: dict[str, Any] = field(default_factory=dict)
    first_run: int = 0
