"""Conformance checks for estimator plugins (``docs/plugins.md``).

A plugin author runs, in their own test suite::

    from quadest.conformance import check_estimator, check_sigma_point_moments
    check_estimator(MyFilter, params={"alpha": 0.5}, bad_params=[{"alpha": -1.0}])
    check_sigma_point_moments(MyFilter, params={"alpha": 0.5, "beta": 2.0, "kappa": 0.0})

Each raises ``AssertionError`` naming the first check that fails.

:func:`check_estimator`:

1. the class meets the contract (subclass, methods, declared capabilities, ``Params``);
2. on a linear-Gaussian model (2-D constant velocity, positions measured, correlated non-identity
   P0, Q, R, three runs with their own data) a Gaussian filter reproduces the Kalman filter
   (filterpy's ``KalmanFilter``) to ``rtol``;
3. shapes of mean, covariance and, when declared, innovation; symmetric covariances;
4. a batch gives each run what that run gives alone (means and covariances);
5. two fresh instances on the same data give identical numbers (an estimator declaring the
   ``"random"`` capability gets one generator per run, the same for run ``i`` in a batch and alone);
6. each entry of ``bad_params`` raises a ``ValueError`` with a message at construction.

On a linear model the sigma-point parameters and the zeroth-point weight W0(c) are invisible.
:func:`check_sigma_point_moments` therefore puts the filter on quadratic models, one predict and
one update from a diagonal P0, and compares with moments written in closed form here, from the
polynomial's coefficients alone (no quadest filter code is involved):

- the UT (Julier & Uhlmann 2004; thesis eqs 5.2–5.9) with parameters α, β, κ, sigma points along
  the columns of a triangular or symmetric square root (both diagonal for a diagonal P), for
  ``x = μ + d``, ``f(μ + d) = f(μ) + G d + [dᵀ C_j d]_j``, ``c_ij = P_ii C_j,ii``, ``t = Σ_i c_i``
  (``t_j = tr(C_j P)``) and ``γ² = α²(n + κ)``, gives exactly::

      mean = f(μ) + t
      cov  = G P Gᵀ + γ² Σ_i c_i c_iᵀ + (β − α²) t tᵀ
      Pxy  = P Gᵀ

  (the t tᵀ coefficient is W0(c) + n/γ² − 2; with W0(c) = λ/(n+λ) + 1 − α² + β it is β − α²).
  The third-degree cubature rule (Arasaratnam & Haykin 2009) is the UT with α = 1, β = 0, κ = 0.
- central differences with step h (Nørgaard, Poulsen & Ravn 2000), whose covariance comes from
  first- and second-order divided differences, give ``cov = G P Gᵀ + (h² − 1) Σ_i c_i c_iᵀ`` with
  the same mean and ``Pxy``;
- a rule exact for Gaussian integrals of polynomials up to degree 5 (fifth-degree cubature,
  Gauss–Hermite with three or more points per axis) gives the exact Gaussian moments::

      mean = f(μ) + t,  cov_jk = (G P Gᵀ)_jk + 2 tr(C_j P C_k P),  Pxy = P Gᵀ

Taking W0(c) from the mean weights, ignoring β, dropping or flipping the W0(c) term, or a wrong
spread γ change ``cov`` by a multiple of ``t tᵀ`` or of ``Σ c_i c_iᵀ``, far beyond round-off.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from filterpy.kalman import KalmanFilter

from quadest.estimators.registry import contract_problems, make_estimator
from quadest.models.functional import FunctionalModel, LinearGaussianModel

__all__ = ["check_estimator", "check_sigma_point_moments", "linear_gaussian_problem", "quadratic_moments"]


def _spd(rng: np.random.Generator, n: int, scale: float) -> np.ndarray:
    A = rng.standard_normal((n, n))
    return scale * (A @ A.T / n + 0.3 * np.eye(n))


def linear_gaussian_problem(runs: int = 3, steps: int = 60, seed: int = 0):
    """``(model, x0, P0, u, z)`` for a 2-D constant-velocity target with position measurements:
    n = 4, m = 2, correlated non-identity P0, Q and R, each run with its own truth and noise."""
    rng = np.random.default_rng(seed)
    dt = 0.1
    A = np.eye(4)
    A[0, 2] = A[1, 3] = dt
    C = np.eye(2, 4)
    Q, R, P0 = _spd(rng, 4, 0.01), _spd(rng, 2, 0.2), _spd(rng, 4, 1.0)
    model = LinearGaussianModel(A, C, Q, R, dt=dt, batch_size=runs)
    LQ, LR, L0 = np.linalg.cholesky(Q), np.linalg.cholesky(R), np.linalg.cholesky(P0)
    x = np.empty((runs, steps + 1, 4))
    x[:, 0] = rng.standard_normal((runs, 4))
    for k in range(1, steps + 1):
        x[:, k] = x[:, k - 1] @ A.T + rng.standard_normal((runs, 4)) @ LQ.T
    z = x @ C.T + rng.standard_normal((runs, steps + 1, 2)) @ LR.T
    x0 = x[:, 0] + rng.standard_normal((runs, 4)) @ L0.T
    u = np.zeros((runs, steps + 1, 0))
    return model, x0, np.broadcast_to(P0, (runs, 4, 4)).copy(), u, z


GENERATOR_SEED = 20260101


def _generators(runs: Sequence[int]) -> list[np.random.Generator]:
    """Run ``i``'s generator is the same in a batch and alone, so a random estimator can be held
    to "a batch gives each run what that run gives alone" and to determinism."""
    children = np.random.SeedSequence(GENERATOR_SEED).spawn(max(runs) + 1)
    return [np.random.default_rng(children[i]) for i in runs]


def _run(est, x0, P0, u, z, runs: Sequence[int] | None = None):
    if "random" in est.capabilities:
        est.set_generators(_generators(range(x0.shape[0]) if runs is None else runs))
    est.initialize(x0.copy(), P0.copy())
    means, covs, innovations = [], [], []
    for k in range(1, z.shape[1]):
        est.predict(u[:, k - 1])
        est.update(z[:, k], u[:, k])
        means.append(np.array(est.mean, copy=True))
        covs.append(np.array(est.covariance, copy=True))
        if "innovation" in est.capabilities:
            innovations.append(tuple(np.array(a, copy=True) for a in est.innovation()))
    return np.array(means), np.array(covs), innovations


def _kalman(model, x0, P0, z):
    xs, Ps = [], []
    for i in range(x0.shape[0]):
        kf = KalmanFilter(dim_x=model.n, dim_z=model.m)
        kf.F, kf.H, kf.Q, kf.R = model.A, model.C, model.Q, model.R
        kf.x, kf.P = x0[i].copy(), P0[i].copy()
        run_x, run_P = [], []
        for k in range(1, z.shape[1]):
            kf.predict()
            kf.update(z[i, k])
            run_x.append(kf.x.copy())
            run_P.append(kf.P.copy())
        xs.append(run_x)
        Ps.append(run_P)
    return np.swapaxes(np.array(xs), 0, 1), np.swapaxes(np.array(Ps), 0, 1)


def _relative(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.abs(a - b).max() / np.abs(b).max())


def check_estimator(
    cls: type,
    params: Mapping[str, Any] | None = None,
    bad_params: Sequence[Mapping[str, Any]] = (),
    gaussian: bool = True,
    rtol: float = 1e-9,
) -> None:
    """Run the conformance checks on estimator class ``cls`` (see the module docstring).

    Args:
        cls: a subclass of ``Estimator`` (batched) or ``SingleRunEstimator``.
        params: constructor parameters for the checks.
        bad_params: parameter sets that must be refused with a ``ValueError``.
        gaussian: whether the filter is a Gaussian filter that must equal the Kalman filter on a
            linear-Gaussian model (a particle filter would pass ``False``).
        rtol: relative tolerance of the Kalman-filter and batch checks.
    """
    name = getattr(cls, "__name__", repr(cls))
    problems = contract_problems(cls)
    assert not problems, f"{name}: contract: {'; '.join(problems)}"
    params = dict(params or {})
    model, x0, P0, u, z = linear_gaussian_problem()
    B, n, m = x0.shape[0], model.n, model.m

    est = make_estimator(cls, model, params)
    xs, Ps, innov = _run(est, x0, P0, u, z)
    K = z.shape[1] - 1
    assert xs.shape == (K, B, n), f"{name}: mean has shape {xs.shape[1:]}, expected {(B, n)}"
    assert Ps.shape == (K, B, n, n), f"{name}: covariance has shape {Ps.shape[1:]}, expected {(B, n, n)}"
    assert np.allclose(Ps, np.swapaxes(Ps, -1, -2), rtol=1e-10, atol=1e-12), f"{name}: covariance not symmetric"
    assert not np.any(est.failed), f"{name}: flagged runs on a benign linear problem: {est.failure_reasons}"
    if "innovation" in est.capabilities:
        nu, S = innov[-1]
        assert np.shape(nu) == (B, m) and np.shape(S) == (B, m, m), (
            f"{name}: innovation shapes {np.shape(nu)}, {np.shape(S)}, expected {(B, m)}, {(B, m, m)}"
        )
    if gaussian:
        xr, Pr = _kalman(model, x0, P0, z)
        assert _relative(xs, xr) <= rtol, f"{name}: mean differs from the Kalman filter by {_relative(xs, xr):.2e}"
        assert _relative(Ps, Pr) <= rtol, (
            f"{name}: covariance differs from the Kalman filter by {_relative(Ps, Pr):.2e}"
        )

    for i in range(B):
        alone = make_estimator(cls, model.select(i), params)
        xi, Pi, _ = _run(alone, x0[i : i + 1], P0[i : i + 1], u[i : i + 1], z[i : i + 1], runs=[i])
        assert _relative(xs[:, i], xi[:, 0]) <= rtol, f"{name}: run {i} in a batch differs from the run alone"
        assert _relative(Ps[:, i], Pi[:, 0]) <= rtol, (
            f"{name}: run {i}'s covariance in a batch differs from the run alone"
        )

    again, _, _ = _run(make_estimator(cls, model, params), x0, P0, u, z)
    assert np.array_equal(again, xs), f"{name}: two fresh instances gave different numbers on the same data"

    for bad in bad_params:
        try:
            make_estimator(cls, model, {**params, **bad})
        except ValueError as exc:
            assert str(exc), f"{name}: bad parameters {dict(bad)} raised ValueError without a message"
        else:
            raise AssertionError(f"{name}: bad parameters {dict(bad)} were accepted")


class Quadratic:
    """``y_j = b_j + (A x)_j + xᵀ C_j x`` with symmetric ``C_j``, vectorised like a model function:
    ``x`` (B, K, n) → (B, K, m)."""

    def __init__(self, b: np.ndarray, A: np.ndarray, C: np.ndarray) -> None:
        self.b, self.A = np.asarray(b, dtype=float), np.asarray(A, dtype=float)
        C = np.asarray(C, dtype=float)
        self.C = 0.5 * (C + np.swapaxes(C, -1, -2))

    def __call__(self, x: np.ndarray, u: np.ndarray | None = None) -> np.ndarray:
        return self.b + x @ self.A.T + np.einsum("bki,jil,bkl->bkj", x, self.C, x)


REFERENCES = ("ut", "central_difference", "gaussian")


def quadratic_moments(
    poly: Quadratic,
    mu: np.ndarray,
    variances: np.ndarray,
    reference: str,
    ut: tuple[float, float, float] = (1.0, 0.0, 0.0),
    h: float = float(np.sqrt(3.0)),
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mean (B, m), covariance (B, m, m) and cross-covariance (B, n, m) of ``poly(x)`` for
    ``x ~ N(μ, diag(variances))``, as a sigma-point rule returns them (closed forms of the module
    docstring): ``reference="ut"`` for the UT with ``ut = (α, β, κ)``, ``"central_difference"``
    for central differences with step ``h``, ``"gaussian"`` for the exact Gaussian moments (rules
    exact to degree 5)."""
    alpha, beta, kappa = ut
    n = mu.shape[-1]
    P = np.diag(variances)
    G = poly.A + 2.0 * np.einsum("jil,bl->bji", poly.C, mu)
    c = variances[:, None] * np.einsum("jii->ij", poly.C)
    t = c.sum(axis=0)
    if reference == "ut":
        spread = alpha**2 * (n + kappa) * (c.T @ c) + (beta - alpha**2) * np.outer(t, t)
    elif reference == "central_difference":
        spread = (h**2 - 1.0) * (c.T @ c)
    else:
        CP = poly.C @ P
        spread = 2.0 * np.einsum("jab,kba->jk", CP, CP)
    mean = poly(mu[:, None])[:, 0] + t
    return mean, G @ P @ np.swapaxes(G, -1, -2) + spread, P @ np.swapaxes(G, -1, -2)


def _quadratic_probe(seed: int = 2024):
    """Fixed coefficients of the probes: n = 4, m = 2, two runs with their own means, a diagonal
    P0 with unequal variances, a near-identity linear part and quadratic terms whose diagonals
    give ``t`` of about 0.2: changing β by 2 changes the covariance by 15–20 %, and the UT
    covariance stays positive definite for α ∈ [1e-3, 1], β ∈ {0, 2}, κ ∈ {−3, 0, 1} (at κ = −3,
    γ² = α²(n + κ) = α², with β − α² = −1 at α = 1, β = 0)."""
    rng = np.random.default_rng(seed)
    n, m = 4, 2
    mu = np.array([[0.3, -0.5, 0.8, 0.1], [-0.4, 0.2, -0.1, 0.6]])
    variances = np.array([0.2, 0.5, 0.3, 0.4])
    q = np.array([0.01, 0.02, 0.015, 0.01])

    def quadratic(rows: int) -> Quadratic:
        C = 0.1 * rng.standard_normal((rows, n, n))
        C[:, np.arange(n), np.arange(n)] = rng.uniform(0.1, 0.25, (rows, n))
        return Quadratic(rng.standard_normal(rows), np.eye(rows, n) + 0.1 * rng.standard_normal((rows, n)), C)

    return mu, variances, q, quadratic(n), quadratic(m)


def _declared(cls: type, params: Mapping[str, Any], keys: tuple[str, ...], hint: str) -> tuple[float, ...]:
    """The values of ``keys`` from ``params``, completed with the defaults of ``cls.Params``."""
    schema = getattr(cls, "Params", None)
    defaults = {f.name: f.default for f in dataclasses.fields(schema)} if dataclasses.is_dataclass(schema) else {}
    values = {**defaults, **params}
    missing = [k for k in keys if k not in values]
    if missing:
        raise ValueError(
            f"this reference needs {list(keys)}; {missing} are neither in params nor in "
            f"{getattr(cls, '__name__', cls)}.Params: {hint}"
        )
    return tuple(float(values[k]) for k in keys)


def _assert_none_flagged(name: str, est, step: str) -> None:
    assert not np.any(est.failed), (
        f"{name}: runs flagged at the {step} of the quadratic probe ({est.failure_reasons}); a negative "
        "W0(c) can make the UT covariance of the probe indefinite: choose other parameters"
    )


def check_sigma_point_moments(
    cls: type,
    params: Mapping[str, Any] | None = None,
    reference: str = "ut",
    ut: tuple[float, float, float] | None = None,
    rtol: float | None = None,
) -> None:
    """Check a sigma-point filter's predict and update on quadratic models against closed forms
    (see the module docstring). The filter must spread its points along a triangular or
    symmetric square root of the covariance and expose the predicted moments through ``mean``
    and ``covariance`` after ``predict``.

    1. predict: ``f`` quadratic (n = 4), P0 diagonal; the predicted mean and covariance must be
       the reference moments of ``f`` plus Q (eqs 5.16–5.19);
    2. update: ``f`` the identity (so the predicted covariance P0 + Q stays diagonal), ``h``
       quadratic (m = 2); the posterior must be the Kalman update with the reference ``ŷ``,
       ``Pyy + R`` and ``Pxy`` (eqs 5.21–5.29).

    Args:
        cls: the estimator class, built like :func:`check_estimator` builds it.
        params: constructor parameters.
        reference: ``"ut"``: the rule is a UT with (α, β, κ) = ``ut``, by default the ``alpha``,
            ``beta``, ``kappa`` of ``params`` completed from ``cls.Params``;
            ``"central_difference"``: divided differences with the step ``h`` of ``params`` or
            ``cls.Params``; ``"gaussian"``: the rule
            is exact for Gaussian integrals of polynomials up to degree 5, so the reference is the
            exact Gaussian moments.
        ut: the (α, β, κ) of a rule that equals a UT without taking those parameters (the
            third-degree cubature rule: ``(1, 0, 0)``).
        rtol: relative tolerance; by default ``100 eps · max(1, n/γ²)``. The references are
            exact, so only the filter's round-off counts, and the UT amplifies it by about
            ``|W0| ≈ n/γ²`` (a second difference at spread γ): ~1e-13 at α = 0.5, ~2e-8 at
            α = 1e-3, where the SR-UKF and filterpy's UKF sit near 1e-9. A wrong W0(c) or β
            changes the covariance by 10 % or more.

    W0(c) and β enter only through ``(β − α²) t tᵀ``: run it with β ≠ 0 and 1 − α² + β ≠ 0
    (for example α = 0.5, β = 2) to expose a W0(c) taken from the mean weights or an ignored β.
    """
    if reference not in REFERENCES:
        raise ValueError(f"reference must be one of {list(REFERENCES)}, got {reference!r}")
    name = getattr(cls, "__name__", repr(cls))
    problems = contract_problems(cls)
    assert not problems, f"{name}: contract: {'; '.join(problems)}"
    params = dict(params or {})
    mu, variances, q, f, h = _quadratic_probe()
    B, n = mu.shape
    rule, step, spread2 = (1.0, 0.0, 0.0), float(np.sqrt(3.0)), float(n)
    if reference == "ut":
        hint = "pass ut=(alpha, beta, kappa) for the UT the rule equals"
        rule = ut if ut is not None else _declared(cls, params, ("alpha", "beta", "kappa"), hint)
        label, spread2 = f"UT(alpha={rule[0]:g}, beta={rule[1]:g}, kappa={rule[2]:g})", rule[0] ** 2 * (n + rule[2])
    elif reference == "central_difference":
        (step,) = _declared(cls, params, ("h",), "the central-difference step must be called h")
        label, spread2 = f"central-difference (h={step:g})", step**2
    else:
        label = "exact Gaussian"
    if rtol is None:
        rtol = 100.0 * np.finfo(float).eps * max(1.0, n / spread2)
    P0 = np.broadcast_to(np.diag(variances), (B, n, n)).copy()
    u = np.zeros((B, 0))
    R = np.array([[0.1, 0.02], [0.02, 0.08]])

    predict_model = FunctionalModel(f, lambda x, u: x[..., :2], np.diag(q), R, batch_size=B)
    est = make_estimator(cls, predict_model, params)
    est.initialize(mu.copy(), P0.copy())
    est.predict(u)
    _assert_none_flagged(name, est, "predict")
    mean, cov, _ = quadratic_moments(f, mu, variances, reference, rule, step)
    for what, got, ref in (("mean", est.mean, mean), ("covariance", est.covariance, cov + np.diag(q))):
        err = _relative(np.asarray(got), ref)
        assert err <= rtol, (
            f"{name}: predicted {what} of a quadratic f differs from the {label} moments by {err:.2e} "
            "(mean weights, W0(c), beta or the spread gamma)"
        )

    update_model = FunctionalModel(lambda x, u: x, h, np.diag(q), R, batch_size=B)
    z = np.array([[0.5, -0.3], [0.2, 0.4]])
    est = make_estimator(cls, update_model, params)
    est.initialize(mu.copy(), P0.copy())
    est.predict(u)
    est.update(z, u)
    _assert_none_flagged(name, est, "update")
    prior = variances + q
    y, Pyy, Pxy = quadratic_moments(h, mu, prior, reference, rule, step)
    Pyy = Pyy + R
    K = np.linalg.solve(Pyy, np.swapaxes(Pxy, -1, -2)).swapaxes(-1, -2)
    x_post = mu + (K @ (z - y)[..., None])[..., 0]
    P_post = np.diag(prior) - K @ Pyy @ np.swapaxes(K, -1, -2)
    for what, got, ref in (("mean", est.mean, x_post), ("covariance", est.covariance, P_post)):
        err = _relative(np.asarray(got), ref)
        assert err <= rtol, (
            f"{name}: updated {what} with a quadratic h differs from the Kalman update with the {label} "
            f"moments by {err:.2e} (W0(c) or beta in Pyy, the cross-covariance Pxy, or the gain)"
        )
