"""Per-run random streams: adding the estimators' stream changed no draw, and every data builder
hands each run its own estimator seed, the same whatever the number of runs."""

from __future__ import annotations

import numpy as np
import pytest

from helpers import compose_config, compose_settings
from quadest.app.settings import data_settings
from quadest.montecarlo.streams import STREAMS, run_seed_sequences, run_streams
from quadest.simulation.registry import build_data

# The streams before the estimators' one was appended, in their spawn order (numpy documents that
# ``SeedSequence(seed).spawn(B)[i].spawn(J)[j]`` is ``SeedSequence(seed, spawn_key=(i, j))``).
HISTORICAL = (
    "start",
    "accel_errors",
    "gyro_errors",
    "accel_noise",
    "gyro_noise",
    "encoder",
    "initial",
    "process",
    "measurement",
)
EXPECTED = (
    *HISTORICAL, "estimator", "state_sensor", "mag_errors", "mag_noise", "gps", "barometer", "vision",
)  # fmt: skip  # append only


def _reference(seed: int, run: int, name: str) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(run, EXPECTED.index(name))))


def _same_seed(a: np.random.SeedSequence, b: np.random.SeedSequence) -> bool:
    return np.array_equal(a.generate_state(8), b.generate_state(8))


def test_existing_streams_keep_their_draws():
    assert STREAMS == EXPECTED
    streams = run_streams(2024, 3)
    for j, name in enumerate(HISTORICAL):
        for i in range(3):
            expected = np.random.default_rng(np.random.SeedSequence(2024, spawn_key=(i, j))).standard_normal(6)
            np.testing.assert_array_equal(streams[name][i].standard_normal(6), expected)


def test_linear_truth_and_measurements_come_from_the_process_and_measurement_streams():
    """An independent recursion x_k = A x_{k-1} + L_Q w_k, z_k = C x_k + L_R v_k with the draws
    of the documented streams reproduces the builder's truth and measurements to round-off."""
    cfg = compose_config(["model=linear", "runs=3", "duration=4", "sample_period=0.5", "seed=11"])
    data = build_data(data_settings(cfg))
    model, (B, K1, n) = data.model, data.truth.shape
    A, C = np.eye(4), np.eye(2, 4)
    A[0, 2] = A[1, 3] = 0.5
    LQ, LR = np.linalg.cholesky(model.Q), np.linalg.cholesky(model.R)
    for i in range(B):
        w = _reference(11, i, "process").standard_normal((K1, n)) @ LQ.T
        v = _reference(11, i, "measurement").standard_normal((K1, 2)) @ LR.T
        x = [np.array(list(cfg.model.initial_state), dtype=float)]
        for k in range(1, K1):
            x.append(A @ x[-1] + w[k])
        x = np.array(x)
        np.testing.assert_allclose(data.truth[i], x, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(data.measurements[i], x @ C.T + v, rtol=1e-12, atol=1e-12)
        x0 = x[0] + np.linalg.cholesky(data.P0) @ _reference(11, i, "initial").standard_normal(n)
        np.testing.assert_allclose(data.x0[i], x0, rtol=1e-12, atol=1e-12)


SMALL = {
    "quadrotor": ["duration=0.2"],
    "linear": ["model=linear", "duration=2", "sample_period=1"],
    "ungm": ["model=ungm", "duration=2", "sample_period=1"],
}


@pytest.mark.parametrize("model", sorted(SMALL))
@pytest.mark.slow
def test_every_builder_gives_each_run_its_estimator_seed(model):
    def seeds(runs: int, seed: int = 5) -> list[np.random.SeedSequence]:
        return build_data(compose_settings([*SMALL[model], f"runs={runs}", f"seed={seed}"])).estimator_seeds

    two, four = seeds(2), seeds(4)
    assert len(two) == 2 and len(four) == 4
    per_run = run_seed_sequences(5, 4)
    for i in range(4):
        expected = np.random.SeedSequence(5, spawn_key=(i, EXPECTED.index("estimator")))
        assert _same_seed(four[i], expected)
        others = [per_run[name][i] for name in HISTORICAL]
        assert not any(_same_seed(four[i], other) for other in others)
    for i in range(2):
        assert _same_seed(two[i], four[i])  # independent of the number of runs
    assert _same_seed(seeds(2)[1], two[1])  # deterministic per (seed, run)
    assert not _same_seed(four[0], four[1])
    assert not _same_seed(seeds(2, seed=6)[0], two[0])
