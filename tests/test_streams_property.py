"""Random streams, as a property over every registered model (``quadest.montecarlo.streams``).

For every model option (the benchmark and validation models included), the flight-log replay and
the closed loop flown on the truth or on its state sensor, the data builder must hand the
estimators run i's ``"estimator"`` stream, ``SeedSequence(seed, spawn_key=(i,
STREAMS.index("estimator")))``, and the data itself (truth, sensors, noise, initial estimates)
must be drawn from other streams of the same ``SeedSequence(seed)`` only: so the estimators' own
draws (particle filters) share no draw with the data's, and every estimator sees the same data
whatever it draws. The test records every generator the builder makes through
``np.random.default_rng`` (which :func:`~quadest.montecarlo.streams.run_streams` uses), keeps
those it drew from, and checks their seeds and their first draws; numpy's global generator must be
left alone. Only the data is built; no estimator runs.
"""

from __future__ import annotations

import numpy as np
import pytest

from helpers import compose_config
from quadest.app.settings import data_settings
from quadest.closed_loop.quadrotor import QuadrotorLoop
from quadest.montecarlo.streams import STREAMS
from quadest.simulation.registry import build_data, model_specs

SEED, RUNS = 31, 3
CONFIGS = {name: [f"model={name}", "duration=0.3"] for name in sorted(model_specs())}
CONFIGS["px4_replay"] = ["experiment=px4_replay", "duration=1.0"]
CONFIGS["closed_loop_truth"] = ["loop=truth", "duration=0.3"]
CONFIGS["closed_loop_measured"] = ["loop=measured", "duration=0.3"]


def build(cfg):
    """The data the estimators get: the open loop's (:func:`build_data`), or, in the closed loop
    flown on the truth or on a noisy state sensor, the measurements of the shared flight."""
    if cfg.loop in ("truth", "measured"):
        return QuadrotorLoop.from_settings(data_settings(cfg)).fly_shared(str(cfg.loop))[1]
    return build_data(data_settings(cfg))


ESTIMATOR = STREAMS.index("estimator")
DRAWS = 256


def first_draws(seq: np.random.SeedSequence) -> set[int]:
    return set(np.random.Generator(np.random.PCG64(seq)).integers(0, 2**63, DRAWS).tolist())


def global_state() -> tuple:
    name, keys, *rest = np.random.get_state()
    return (name, keys.tobytes(), *rest)


def drawn_from(seed, generator: np.random.Generator) -> bool:
    fresh = np.random.default_rng(seed) if isinstance(seed, np.random.SeedSequence) else None
    return fresh is None or fresh.bit_generator.state != generator.bit_generator.state


@pytest.mark.parametrize("name", sorted(CONFIGS))
@pytest.mark.slow
def test_estimators_get_the_estimator_stream_and_share_no_draw_with_the_data(name, monkeypatch):
    cfg = compose_config([*CONFIGS[name], f"seed={SEED}", f"runs={1 if name == 'px4_replay' else RUNS}"])
    made: list[tuple[object, np.random.Generator]] = []
    default_rng = np.random.default_rng

    def recording_default_rng(seed=None):
        generator = default_rng(seed)
        made.append((seed, generator))
        return generator

    before = global_state()
    monkeypatch.setattr(np.random, "default_rng", recording_default_rng)
    data = build(cfg)
    monkeypatch.undo()
    runs = data.truth.shape[0]
    assert global_state() == before, f"{name}: the data builder drew from numpy's global generator"

    seeds = data.estimator_seeds
    assert len(seeds) == runs
    for i, seq in enumerate(seeds):
        assert isinstance(seq, np.random.SeedSequence)
        assert (seq.entropy, tuple(seq.spawn_key)) == (SEED, (i, ESTIMATOR)), f"run {i} got another stream"

    used = [seed for seed, generator in made if drawn_from(seed, generator)]
    assert used or cfg.get("source") is not None, f"{name}: no draw recorded (a log replay draws none)"
    for seed in used:
        assert isinstance(seed, np.random.SeedSequence) and seed.entropy == SEED, (
            f"{name}: data drawn from a generator seeded with {seed!r}, not from a stream of SeedSequence(seed)"
        )
        assert len(seed.spawn_key) == 2 and seed.spawn_key[1] != ESTIMATOR, (
            f"{name}: the data drew from the estimators' stream {seed.spawn_key}"
        )
    estimator_draws = set().union(*(first_draws(seq) for seq in seeds))
    for seed in used:
        assert not first_draws(seed) & estimator_draws, f"{name}: stream {seed.spawn_key} shares draws"
