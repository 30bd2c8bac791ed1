"""The estimator interface, and the adapter that runs a single-run estimator over a batch.

A batched estimator (:class:`Estimator`) advances every Monte Carlo run of a batch at once:
means (B, n), covariances (B, n, n), inputs (B, nu), measurements (B, m). A single-run estimator
(:class:`SingleRunEstimator`) sees one run at a time, with the batch axis dropped; the runner
wraps it in :class:`PerRunAdapter`, so both kinds look the same from outside.

Optional capabilities are declared in ``capabilities``, never guessed:

- ``"innovation"``: after ``update``, :meth:`Estimator.innovation` returns the innovation
  ``ν = z − ẑ`` and the lower factor of its covariance (for NIS);
- ``"sqrt_covariance"``: :attr:`Estimator.sqrt_covariance` is the filter's own factor;
- ``"random"``: the estimator draws random numbers. Before ``initialize`` the runner hands it one
  ``np.random.Generator`` per run (:meth:`Estimator.set_generators`), made from that run's
  ``"estimator"`` stream of the experiment's ``SeedSequence``, separate from the truth and sensor
  streams. Every random estimator of a job gets fresh generators from the same seeds (common
  random numbers between estimators), so adding one changes no other estimator's numbers;
- ``"cloud"``: the covariance is a summary of a sample (a particle cloud), not the filter's state.
  When it is singular (a cloud collapsed onto one particle) the NEES is unavailable at that step
  and left out of the NEES averages; the run is not taken for diverged.
- ``"no_covariance"``: the filter has no covariance of the error state (a complementary filter);
  its ``covariance`` is NaN, its NEES unavailable, and neither makes the run diverged.
- ``"smoothing"``: with :attr:`Estimator.smoothing` set before ``initialize``, every ``predict``
  leaves the smoother's step of its transition in ``smoother_step``
  (:class:`~quadest.estimators.smoothing.SmootherStep`) and ``smoothing_form()`` says how the
  steps combine (:mod:`quadest.estimators.smoothing`: fixed interval and fixed lag).
- ``"iterated_smoothing"``: besides ``"smoothing"``, the estimator re-linearises the whole run
  about its smoothed trajectory: ``iterated_smoothing(iterations, means, covariances)`` returns
  the smoothed means and covariances of steps 0..K (the IERTS and IPLS,
  :mod:`quadest.estimators.iterated_smoothing`).
- ``"particle_smoothing"``: with :attr:`Estimator.smoothing` set, every ``update`` leaves its
  weighted cloud before resampling in ``smoother_cloud``
  (:class:`~quadest.estimators.particle_smoothing.ParticleCloud`) for the backward simulation.

An estimator may also report per-run diagnostics at the end of a run (:meth:`Estimator.diagnostics`:
effective sample size, resampling counts, ...); they become columns of ``metrics.csv``.

A run that fails (a downdate that would make a covariance indefinite, a non-finite number, an
exception inside a single-run estimator) is *flagged*: ``failed[i]`` becomes true and
``failure_reasons[i]`` says why. The other runs carry on unchanged.
"""

from __future__ import annotations

import functools
import inspect
from abc import ABC, abstractmethod
from typing import ClassVar

import numpy as np

from quadest.errors import ConfigError, FilterDivergence
from quadest.estimators.params import parameter_problem
from quadest.estimators.smoothing import SmootherStep, SmoothingForm
from quadest.models.base import FilterModel
from quadest.numerics.square_root import warm_up

CAPABILITIES = frozenset(
    {
        "innovation",
        "sqrt_covariance",
        "random",
        "cloud",
        "no_covariance",
        "smoothing",
        "iterated_smoothing",
        "particle_smoothing",
    }
)


class _FailureLog:
    """Which runs of a batch failed, and why (the first reason is kept)."""

    failed: np.ndarray
    failure_reasons: dict[int, str]

    def _reset_failures(self, batch: int) -> None:
        self.failed = np.zeros(batch, dtype=bool)
        self.failure_reasons = {}

    def flag(self, runs, reason: str) -> None:
        for r in np.atleast_1d(runs):
            r = int(r)
            if not self.failed[r]:
                self.failed[r] = True
                self.failure_reasons[r] = reason


class _DeclaredParameters:
    """Checks the declared parameter ranges and constraints of ``Params``
    (:func:`~quadest.estimators.params.parameter_problem`) whenever an estimator is constructed,
    before its own ``__init__`` runs: every subclass's ``__init__`` is wrapped, and the outermost
    call checks the arguments against the class of the instance being built. A value the pre-run
    validation refuses is thus refused by a direct construction too, with a one-line
    :class:`~quadest.errors.ConfigError` naming the estimator and the key (``srukf.beta=nan ...``)."""

    Params: ClassVar[type | None] = None
    config_name: ClassVar[str | None] = None

    def __init_subclass__(cls, **kwargs) -> None:
        super().__init_subclass__(**kwargs)
        init = cls.__dict__.get("__init__")
        if init is None:
            return
        signature = inspect.signature(init)

        @functools.wraps(init)
        def checked_init(self, *args, **kw) -> None:
            if not getattr(self, "_parameters_checked", False):
                self._parameters_checked = True
                bound = signature.bind(self, *args, **kw)
                bound.apply_defaults()
                values = dict(bound.arguments)
                model = values.pop("model", None)
                values.pop("self")
                for name, parameter in signature.parameters.items():
                    if parameter.kind is inspect.Parameter.VAR_KEYWORD:
                        values.update(values.pop(name))
                    elif parameter.kind is inspect.Parameter.VAR_POSITIONAL:
                        values.pop(name)
                problem = parameter_problem(type(self).Params, values, getattr(model, "n", 0))
                if problem is not None:
                    key, value, allowed = problem
                    name = type(self).config_name
                    raise ConfigError(f"{name}.{key}" if name else key, value, allowed)
            init(self, *args, **kw)

        cls.__init__ = checked_init


class Estimator(_DeclaredParameters, _FailureLog, ABC):
    """A filter that advances a batch of runs: leading axis ``B`` on every array.

    A concrete estimator sets ``config_name`` (its name under ``conf/estimator/``) and ``Params``
    (the dataclass of its config parameters, whose fields are its constructor's keyword
    arguments besides ``model``).
    """

    batched: ClassVar[bool] = True
    capabilities: ClassVar[frozenset[str]] = frozenset()
    config_name: ClassVar[str | None] = None
    Params: ClassVar[type | None] = None
    smoothing: bool = False  # record the smoother's steps (capability "smoothing")

    def __init__(self, model: FilterModel) -> None:
        self.model = model
        warm_up(model)  # compiled kernels loaded here, not in the first timed step

    @abstractmethod
    def initialize(self, x0: np.ndarray, P0: np.ndarray) -> None:
        """Start every run from mean ``x0`` (B, n) and covariance ``P0`` (B, n, n)."""

    @abstractmethod
    def predict(self, u: np.ndarray) -> None:
        """Time update with the input ``u`` (B, nu) of the previous sample."""

    @abstractmethod
    def update(self, z: np.ndarray, u: np.ndarray, sensor: str | None = None) -> None:
        """Measurement update with ``z`` (B, m) and the input ``u`` (B, nu) at that sample;
        ``sensor`` names one of ``model.sensors`` (``None``: the primary measurement)."""

    @property
    @abstractmethod
    def mean(self) -> np.ndarray:
        """Current estimate (B, n)."""

    @property
    @abstractmethod
    def covariance(self) -> np.ndarray:
        """Current covariance (B, n, n)."""

    @property
    def sqrt_covariance(self) -> np.ndarray:
        """Lower factor of the current covariance (B, n, n), for estimators that declare the
        ``"sqrt_covariance"`` capability."""
        raise AttributeError(f"{type(self).__name__} does not declare the 'sqrt_covariance' capability")

    def innovation(self) -> tuple[np.ndarray, np.ndarray]:
        """Last innovation (B, m) and the lower factor of its covariance (B, m, m)."""
        raise AttributeError(f"{type(self).__name__} does not declare the 'innovation' capability")

    def set_generators(self, rngs: list[np.random.Generator]) -> None:
        """Receive one generator per run (``"random"`` capability); called before ``initialize``."""
        self.rngs = list(rngs)

    def diagnostics(self) -> dict[str, np.ndarray]:
        """Per-run numbers (name → (B,)) describing the finished run; none by default."""
        return {}

    def quarantine(self, mean: np.ndarray, spread: np.ndarray, safe_mean: np.ndarray, safe_spread: np.ndarray) -> None:
        """Flag runs whose mean or ``spread`` (covariance or its factor) stopped being finite, and
        park every failed run on finite placeholder values in place, so that it cannot disturb
        the arithmetic of the others (every batched operation works run by run)."""
        finite = np.isfinite(mean).all(-1) & np.isfinite(spread).all((-2, -1))
        if not finite.all():
            self.flag(np.flatnonzero(~finite), "non-finite mean or covariance")
        if self.failed.any():
            mean[self.failed] = safe_mean[self.failed]
            spread[self.failed] = safe_spread[self.failed]


class SingleRunEstimator(_DeclaredParameters, ABC):
    """A filter that works on one run: means (n,), covariances (n, n), inputs (nu,), z (m,).

    ``model`` is bound to that single run (a batch of one). Exceptions raised in any method mark
    the run as failed in the adapter; they never stop the other runs.
    """

    capabilities: ClassVar[frozenset[str]] = frozenset()
    config_name: ClassVar[str | None] = None
    Params: ClassVar[type | None] = None
    smoothing: bool = False
    """With capability ``"smoothing"``: every ``predict`` leaves this run's step in ``smoother_step``
    (a :class:`~quadest.estimators.smoothing.SmootherStep` without the batch axis) and
    ``smoothing_form()`` says how the steps combine; :class:`PerRunAdapter` stacks them."""

    def __init__(self, model: FilterModel) -> None:
        self.model = model

    @abstractmethod
    def initialize(self, x0: np.ndarray, P0: np.ndarray) -> None: ...

    @abstractmethod
    def predict(self, u: np.ndarray) -> None: ...

    @abstractmethod
    def update(self, z: np.ndarray, u: np.ndarray) -> None:
        """Primary measurement update; a filter that handles ``model.sensors`` also takes a
        keyword ``sensor`` (the name) and uses that sensor's ``h`` and ``R``."""

    @property
    @abstractmethod
    def mean(self) -> np.ndarray: ...

    @property
    @abstractmethod
    def covariance(self) -> np.ndarray: ...

    def innovation(self) -> tuple[np.ndarray, np.ndarray]:
        """Last innovation (m,) and the lower Cholesky factor of its covariance (m, m), the same
        meaning as :meth:`Estimator.innovation`."""
        raise AttributeError(f"{type(self).__name__} does not declare the 'innovation' capability")

    def set_generator(self, rng: np.random.Generator) -> None:
        """Receive this run's generator (``"random"`` capability); called before ``initialize``."""
        self.rng = rng


class PerRunAdapter(Estimator):
    """Runs one :class:`SingleRunEstimator` per run of the batch behind the batched interface.

    This is the only place where the framework loops over runs in Python.
    """

    batched: ClassVar[bool] = False

    def __init__(self, model: FilterModel, factory, **params) -> None:
        super().__init__(model)
        self.filters: list[SingleRunEstimator] = [factory(model.select(i), **params) for i in range(model.batch_size)]
        self._capabilities = frozenset(getattr(factory, "capabilities", frozenset())) - {"sqrt_covariance"}
        self._reset_failures(model.batch_size)
        self._mean = np.full((model.batch_size, model.n), np.nan)
        self._cov = np.full((model.batch_size, model.n_err, model.n_err), np.nan)

    def _each(self, call) -> None:
        """``call(i, filter)`` for every live run, then collect the means and covariances. A run
        that raises, or whose mean (or known covariance) is not finite, is flagged and keeps its
        last finite values; the finiteness check runs once for the batch."""
        previous = self._mean.copy(), self._cov.copy()
        stepped = []
        for i, filt in enumerate(self.filters):
            if self.failed[i]:
                continue
            try:
                call(i, filt)
                self._mean[i], self._cov[i] = filt.mean, filt.covariance
                stepped.append(i)
            except ConfigError:  # a configuration the plugin refuses fails the job (docs/usage.md), no run "diverges"
                raise
            except Exception as exc:  # a plugin's failure marks its run, never the job
                reason = exc.reason if isinstance(exc, FilterDivergence) else f"{type(exc).__name__}: {exc}"
                self._mean[i], self._cov[i] = previous[0][i], previous[1][i]
                self.flag(i, reason)
        runs = np.asarray(stepped, dtype=int)
        finite = np.isfinite(self._mean[runs]).all(-1)
        if "no_covariance" not in self._capabilities:
            finite &= np.isfinite(self._cov[runs]).all((-2, -1))
        bad = runs[~finite]
        if bad.size:
            self._mean[bad], self._cov[bad] = previous[0][bad], previous[1][bad]
            self.flag(bad, "non-finite mean or covariance")

    def _park_failed_rows(self, rows: np.ndarray) -> np.ndarray:
        """``rows`` (B, ...) with each failed run's row replaced by the first live run's, so a
        batched model call on them raises no floating-point warnings (those rows are ignored)."""
        if self.failed.any():
            rows = rows.copy()
            rows[self.failed] = rows[np.argmin(self.failed)]
        return rows

    @property
    def capabilities(self) -> frozenset[str]:  # type: ignore[override]
        """The wrapped class's capabilities (the adapter has no factor of its own)."""
        return self._capabilities

    @property
    def smoothing(self) -> bool:  # type: ignore[override]
        """Whether every run's filter records its smoother steps (set before ``initialize``)."""
        return all(filt.smoothing for filt in self.filters)

    @smoothing.setter
    def smoothing(self, on: bool) -> None:
        for filt in self.filters:
            filt.smoothing = on

    @property
    def smoother_step(self) -> SmootherStep:
        """The runs' steps of the last predict stacked; a failed run (left out of the smoothed
        result) gets a zero gain, an identity residual and its last mean."""
        n, B = self.model.n_err, len(self.filters)
        gain, residual = np.zeros((B, n, n)), np.broadcast_to(np.eye(n), (B, n, n)).copy()
        predicted = self._mean.copy()
        for i, filt in enumerate(self.filters):
            if not self.failed[i]:
                step = filt.smoother_step
                gain[i], residual[i], predicted[i] = step.gain, step.residual, step.predicted_mean
        return SmootherStep(gain, predicted, residual)

    def smoothing_form(self) -> SmoothingForm:
        """The wrapped filters' form (the same for every run)."""
        return self.filters[0].smoothing_form()

    def set_generators(self, rngs: list[np.random.Generator]) -> None:
        for filt, rng in zip(self.filters, rngs, strict=True):
            filt.set_generator(rng)

    def initialize(self, x0: np.ndarray, P0: np.ndarray) -> None:
        self._reset_failures(len(self.filters))
        self._each(lambda i, f: f.initialize(x0[i], P0[i]))

    def predict(self, u: np.ndarray) -> None:
        self._each(lambda i, f: f.predict(u[i]))

    def update(self, z: np.ndarray, u: np.ndarray, sensor: str | None = None) -> None:
        if sensor is None:
            self._each(lambda i, f: f.update(z[i], u[i]))
        else:
            self._each(lambda i, f: f.update(z[i], u[i], sensor=sensor))

    @property
    def mean(self) -> np.ndarray:
        return self._mean

    @property
    def covariance(self) -> np.ndarray:
        return self._cov

    def innovation(self) -> tuple[np.ndarray, np.ndarray]:
        """Each live run's innovation and factor, stacked; NaN for failed runs and for a run whose
        filter cannot give them (an innovation covariance that is not positive definite)."""
        B = len(self.filters)
        live = {}
        for i, filt in enumerate(self.filters):
            if self.failed[i]:
                continue
            try:
                live[i] = filt.innovation()
            except Exception:  # a run without a usable innovation gets NaN, never a crash
                continue
        m = np.size(next(iter(live.values()))[0]) if live else self.model.m
        nu, Sy = np.full((B, m), np.nan), np.full((B, m, m), np.nan)
        for i, (v, L) in live.items():
            nu[i], Sy[i] = np.ravel(v), L
        return nu, Sy
