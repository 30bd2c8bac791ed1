"""Conformance checks for model plugins (``docs/models.md``): :func:`check_model`.

At true states of a simulated flight, mid-flight and at its end (a registered model option: its own ``build`` from the
config ``quadest model=<name>`` composes) or at states the caller gives (a bare filter model):

1. shapes: ``f`` (B, K, n) and ``h`` (B, K, m) of ``x`` (B, K, n), ``Q`` square, ``R`` (m, m);
2. Jacobians: every analytic Jacobian the model declares against central differences: for a
   vector state ``F_analytic`` and ``H_analytic`` against
   :meth:`~quadest.models.base.FilterModel.jacobian_fd` (steps ``fd_step·max(1, |x_j|)``); for a
   state on a manifold (``boxplus``) ``F_err_analytic`` and ``H_err_analytic``, also for each of
   its further sensors, against
   :meth:`~quadest.models.base.FilterModel.manifold_jacobian_fd` (points ``x ⊞ (±h e_j)``,
   ``f`` differenced with ``boxminus``) (Solà 2017, eqs. 269 and 279); a model without an
   analytic Jacobian is differenced by the filters themselves, so there is nothing to compare;
3. batch selection: the model restricted to run ``i`` (``select(i)``) and to a slice of runs gives
   those runs' rows of ``f``, ``h`` and their Jacobians on the whole batch, and its
   ``batch_size`` is the number of runs kept.

Each failure raises ``AssertionError`` naming the model and the first check that fails.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from quadest.conformance.compose import compose_settings
from quadest.conformance.jacobians import assert_jacobian
from quadest.models.base import FilterModel
from quadest.simulation.spec import ModelSpec, spec_problems

__all__ = ["check_model"]

BATCH_RTOL = 64 * np.finfo(float).eps
"""Rows of a batch against the run alone: the same arithmetic, up to the order in which a
vectorised reduction sums (a few ulps of the largest value)."""


def _flight(spec: ModelSpec, overrides: Sequence[str], runs: int, seed: int):
    """The filter model of ``quadest model=<name>`` and ``(x, u)`` mid-flight and at the last
    step: true states and the inputs the filters receive (measured input and companions). Not
    the start: a vehicle at rest can sit where a model is not differentiable (the MIMU's
    scale-factor asymmetry ``a·sgn(y)·y`` at zero horizontal specific force), where central
    differences mean nothing."""
    data = spec.build(compose_settings([f"model={spec.name}", f"runs={runs}", f"seed={seed}", *overrides]))
    model, K = data.model, data.time.size - 1
    points = [
        (data.truth[:, k], model.filter_input(data.inputs[:, k], data.companion_truth[:, k])) for k in (K // 2, K)
    ]
    return model, points


def check_model(
    model: ModelSpec | FilterModel,
    states: np.ndarray | None = None,
    inputs: np.ndarray | None = None,
    overrides: Sequence[str] = (),
    runs: int = 3,
    seed: int = 11,
) -> None:
    """Run the conformance checks on a model (see the module docstring).

    Args:
        model: a registered :class:`~quadest.simulation.spec.ModelSpec` (its data is built from the
            config ``model=<name>`` with ``overrides``), or a filter model bound to a batch.
        states: with a filter model, the states (B, n) to check at, one per run of its batch.
        inputs: with a filter model, the inputs (B, nu) at those states.
        overrides: further overrides of a spec's job (``duration=2``), as on the command line.
        runs: the spec's Monte Carlo runs (at least 2, for batch selection).
        seed: the spec's job seed.
    """
    if isinstance(model, ModelSpec):
        problems = spec_problems(model)
        assert not problems, f"model={model.name}: contract: {'; '.join(problems)}"
        label = f"model={model.name}"
        filter_model, points = _flight(model, overrides, runs, seed)
    else:
        if states is None or inputs is None:
            raise ValueError("check_model of a filter model needs its states (B, n) and inputs (B, nu)")
        label, filter_model = getattr(model, "name", type(model).__name__), model
        points = [(np.asarray(states, dtype=float), np.asarray(inputs, dtype=float))]
    B = points[0][0].shape[0]
    assert filter_model.batch_size == B, f"{label}: batch_size {filter_model.batch_size}, but {B} runs"
    assert B >= 2, f"{label}: batch selection needs at least 2 runs, got {B}"
    for x, u in points:
        _check_shapes(label, filter_model, x, u)
        _check_jacobians(label, filter_model, x, u)
        _check_selection(label, filter_model, x, u)


def _check_shapes(label: str, model: FilterModel, x: np.ndarray, u: np.ndarray) -> None:
    B, n, m = x.shape[0], model.n, model.m
    assert x.shape == (B, n), f"{label}: states have shape {x.shape}, expected {(B, n)} (n = {n})"
    fx, hx = model.f(x[:, None], u), model.h(x[:, None], u)
    assert fx.shape == (B, 1, n), f"{label}: f has shape {fx.shape}, expected {(B, 1, n)}"
    assert hx.shape == (B, 1, m), f"{label}: h has shape {hx.shape}, expected {(B, 1, m)}"
    Q, R = np.asarray(model.Q), np.asarray(model.R)
    assert Q.ndim >= 2 and Q.shape[-1] == Q.shape[-2], f"{label}: Q has shape {Q.shape}, not square"
    assert R.shape[-2:] == (m, m), f"{label}: R has shape {R.shape}, expected {(m, m)}"


def _jacobians(model: FilterModel, x: np.ndarray, u: np.ndarray) -> list[tuple[str, np.ndarray, np.ndarray, float]]:
    """(name, analytic, central differences, largest step) of each analytic Jacobian ``model``
    declares at ``x``."""
    found = []
    if model.has_manifold_state:
        F = model.F_err_analytic(x, u)
        if F is not None:
            found.append(("F_err", F, model.manifold_jacobian_fd(model.f, x, u, state_valued=True), model.fd_step))
        for sensor in (None, *model.sensors):
            H = model.H_err_analytic(x, u, sensor)
            if H is not None:
                fd = model.manifold_jacobian_fd(model.measurement(sensor).h, x, u, state_valued=False)
                found.append((f"H_err[{sensor or 'h'}]", H, fd, model.fd_step))
        return found
    largest = model.fd_step * float(np.abs(x).max(initial=1.0))
    F, H = model.F_analytic(x, u), model.H_analytic(x, u)
    if F is not None:
        found.append(("F", F, model.jacobian_fd(model.f, x, u), largest))
    if H is not None:
        found.append(("H", H, model.jacobian_fd(model.h, x, u), largest))
    return found


def _check_jacobians(label: str, model: FilterModel, x: np.ndarray, u: np.ndarray) -> None:
    y = np.concatenate([model.f(x[:, None], u).ravel(), model.h(x[:, None], u).ravel()])
    for name, analytic, differences, largest in _jacobians(model, x, u):
        assert_jacobian(f"{label}: {name}", analytic, differences, y, model.fd_step, largest)


def _check_selection(label: str, model: FilterModel, x: np.ndarray, u: np.ndarray) -> None:
    B = x.shape[0]
    whole = {"f": model.f(x[:, None], u), "h": model.h(x[:, None], u)}
    whole.update({name: J for name, J, _, _ in _jacobians(model, x, u)})
    for runs in [*range(B), slice(1, None)]:
        rows = np.arange(B)[runs] if isinstance(runs, slice) else np.array([runs])
        part = model.select(runs)
        assert part.batch_size == rows.size, (
            f"{label}: select({runs}) has batch_size {part.batch_size}, expected {rows.size}"
        )
        xs, us = x[rows], u[rows]
        alone = {"f": part.f(xs[:, None], us), "h": part.h(xs[:, None], us)}
        alone.update({name: J for name, J, _, _ in _jacobians(part, xs, us)})
        for name, value in whole.items():
            got = np.asarray(alone[name])
            assert got.shape == value[rows].shape, (
                f"{label}: {name} of select({runs}) has shape {got.shape}, expected {value[rows].shape}"
            )
            scale = float(np.abs(value).max(initial=1.0))
            err = float(np.abs(got - value[rows]).max(initial=0.0))
            assert err <= BATCH_RTOL * scale, (
                f"{label}: {name} of select({runs}) differs from those runs' rows of the whole batch by {err:.2e}"
            )
