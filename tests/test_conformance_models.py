"""``quadest.conformance.check_model``: every registered model option passes it; a model with a
Jacobian 0.1 % off, one that forgets to narrow a per-run array when a batch is restricted to some
runs, and one whose selection hands run i the next run's values each fail it, on their bug."""

from __future__ import annotations

import numpy as np
import pytest

from plugin_site import fenced_blocks
from quadest.conformance import check_model
from quadest.models.base import FilterModel
from quadest.simulation.registry import model_specs

SHORT = {"attitude", "ins", "quadrotor", "seed001_rates", "seed003_attitude"}
"""Options flying the quadrotor for 20 s by default: 6 s keep mid-flight off the vehicle at rest."""


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(model_specs()))
def test_every_registered_model_conforms(name):
    check_model(model_specs()[name], overrides=["duration=6"] if name in SHORT else [])


A = np.array([[1.0, 0.1, 0.0], [0.0, 1.0, 0.1], [-0.05, 0.0, 0.98]])


class Drift(FilterModel):
    """``x⁺ = A x + c_i`` with a drift ``c_i`` of each run, ``z = sin(x₁, x₂)``, with their
    analytic Jacobians ``A`` and ``diag(cos)``."""

    name, n, m, nu, dt = "drift", 3, 2, 0, 0.1
    state_names, state_units, measurement_names = ("a", "b", "c"), ("-",) * 3, ("sa", "sb")

    def __init__(self, drift: np.ndarray) -> None:
        self.drift = np.asarray(drift, dtype=float)
        self.batch_size = self.drift.shape[0]
        self.Q, self.R = 0.01 * np.eye(3), 0.1 * np.eye(2)

    def f(self, x, u):
        return x @ A.T + self.drift[:, None, :]

    def h(self, x, u):
        return np.sin(x[..., :2])

    def F_analytic(self, x, u):
        return np.broadcast_to(A, (x.shape[0], 3, 3)).copy()

    def H_analytic(self, x, u):
        H = np.zeros((x.shape[0], 2, 3))
        H[:, [0, 1], [0, 1]] = np.cos(x[:, :2])
        return H

    def _per_run_arrays(self):
        return ("drift",)


class WrongJacobian(Drift):
    def H_analytic(self, x, u):
        return 1.001 * super().H_analytic(x, u)


class ForgetsItsDrift(Drift):
    """A per-run array not declared: ``select`` keeps every run's drift."""

    def _per_run_arrays(self):
        return ()


class NextRun(Drift):
    """``select(i)`` hands run i the drift of run i + 1."""

    def select(self, runs):
        other = super().select(runs)
        if isinstance(runs, int):
            other.drift = self.drift[[(runs + 1) % self.batch_size]]
        return other


def _problem(cls: type[Drift]):
    rng = np.random.default_rng(4)
    return cls(rng.standard_normal((3, 3))), rng.standard_normal((3, 3)), np.zeros((3, 0))


def test_a_conforming_model_passes():
    model, x, u = _problem(Drift)
    check_model(model, x, u)


@pytest.mark.parametrize(
    ("cls", "message"),
    [
        pytest.param(WrongJacobian, "drift: H differs from central differences", id="WrongJacobian"),
        pytest.param(ForgetsItsDrift, r"f of select\(0\) has shape \(3, 1, 3\)", id="ForgetsItsDrift"),
        pytest.param(NextRun, r"f of select\(0\) differs from those runs' rows", id="NextRun"),
    ],
)
def test_a_broken_model_fails_on_its_bug(cls, message):
    model, x, u = _problem(cls)
    with pytest.raises(AssertionError, match=message):
        check_model(model, x, u)


def test_a_bare_filter_model_needs_its_states():
    with pytest.raises(ValueError, match="needs its states"):
        check_model(_problem(Drift)[0])


@pytest.mark.slow
def test_the_kit_example_of_the_plugins_page_runs():
    """The first block of docs/plugins.md's "Conformance" section, executed as written: every test
    it defines passes."""
    text = fenced_blocks("plugins.md")
    block = next(b for b in text if "from quadest.conformance import check_estimator, check_model" in b)
    namespace: dict = {}
    exec(compile(block, "docs/plugins.md", "exec"), namespace)
    tests = [fn for name, fn in namespace.items() if name.startswith("test_")]
    assert len(tests) == 4
    for test in tests:
        test()
