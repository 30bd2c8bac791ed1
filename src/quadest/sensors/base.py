"""What a further sensor is: one :class:`Sensor` class, registered once (docs/sensors.md).

A sensor beside a model's primary measurement (an INS's GPS, barometer, camera and magnetometer;
any sensor a plugin adds, on ``model=ins`` as on ``model=quadrotor``) is one class that carries:

- ``config_name``: its name in ``model.aiding``;
- ``Settings``: the dataclass of its settings node (``sensor.<name>`` unless ``settings_key``
  says otherwise), so a misspelled key fails at composition;
- :meth:`Sensor.validate`: range checks before any work, one line naming the key
  (:func:`check_rate` and :func:`~quadest.sensors.noise_laws.check_noise_law` for the common
  ``rate`` and ``noise_law`` settings);
- :meth:`Sensor.simulate`: its samples of the truth (:class:`TrueMotion`), drawn only from its own
  random streams (``streams``), at its rate and availability (:class:`SensorRecord`), its noise
  under its own law;
- :meth:`Sensor.measurement_model`: what the filters use, a :class:`SensorModel` with ``h``, the
  analytic Jacobian on the model's error state and the noise covariance ``R``.

A sensor never sees a model's state layout: its ``h`` reads named quantities (``measures``:
``position``, ``velocity``, ``attitude``, ...) through the model's :class:`StateLayout`, and its
Jacobian is written with respect to those quantities and placed on the error state by
:meth:`SensorModel.place`. A model offers the quantities its filter state holds, so the same
sensor runs on every model that has what it measures.
"""

from __future__ import annotations

import dataclasses
import inspect
from abc import ABC, abstractmethod
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from quadest.config.ranges import require_positive
from quadest.errors import ConfigError
from quadest.sensors.noise_laws import check_noise_law
from quadest.sensors.record import SensorRecord

QUANTITIES = {
    "position": "earth-frame position p (3), m, z up",
    "velocity": "earth-frame velocity v (3), m/s",
    "attitude": "attitude quaternion q (4, scalar first, body → earth); its error is the body-frame rotation "
    "vector δθ with q_true = q ⊗ exp(δθ) (3 error columns)",
    "platform_position": "the known position of a moving beacon platform (3), m, an input (no error columns)",
}
"""The quantities a model may offer its further sensors, and their conventions."""


@dataclass(frozen=True)
class StateLayout:
    """Where a filter model keeps the quantities its further sensors measure.

    Attributes:
        n_err: the error-state dimension (the Jacobians' columns).
        state: quantity → slice of the state ``x`` holding it.
        error: quantity → slice of the error state it moves one to one (its Jacobian is the
            identity there and zero elsewhere).
        inputs: quantity → slice of the input ``u`` holding it (known, not estimated: a zero
            Jacobian).
    """

    n_err: int
    state: Mapping[str, slice] = field(default_factory=dict)
    error: Mapping[str, slice] = field(default_factory=dict)
    inputs: Mapping[str, slice] = field(default_factory=dict)

    @property
    def quantities(self) -> tuple[str, ...]:
        """The quantities offered, state ones first."""
        return (*self.state, *self.inputs)

    def value(self, name: str, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Quantity ``name`` at states ``x`` (B, K, n) or (B, n) → (B, K, d) or (B, d); an input
        quantity is read from ``u`` (B, nu) → (B, d)."""
        if name in self.state:
            return x[..., self.state[name]]
        return u[:, self.inputs[name]]

    def jacobian(self, name: str, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """``∂ quantity / ∂δx`` (B, d, n_err) at ``x`` (B, n)."""
        if name in self.inputs:
            return np.zeros((x.shape[0], self.value(name, x, u).shape[-1], self.n_err))
        cols = self.error[name]
        width = cols.stop - cols.start
        J = np.zeros((x.shape[0], width, self.n_err))
        J[:, :, cols] = np.eye(width)
        return J


@dataclass(frozen=True)
class TrueMotion:
    """The truth a sensor measures: ``time`` (K+1,), ``position`` and ``velocity`` (B, K+1, 3)
    earth frame z up, ``attitude`` (B, K+1, 4) quaternion body → earth, and ``platform`` (K+1, 3),
    the moving beacon platform's position (``None``: no moving platform)."""

    time: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    attitude: np.ndarray
    platform: np.ndarray | None = None


@dataclass(frozen=True)
class SensorContext:
    """The job settings every sensor may read: ``sample_period`` and ``duration`` (s),
    ``error_scale`` (the MIMU's, for sensors that scale with it), ``calibrated`` (the filters know
    each run's deterministic sensor errors) and ``noise_inflation`` (multiplies every ``R``)."""

    sample_period: float
    duration: float
    error_scale: float = 1.0
    calibrated: bool = True
    noise_inflation: float = 1.0


class SensorModel(ABC):
    """A further sensor as the filters see it: ``h(x, u)`` (B, K, m), ``jacobian(x, u)``
    (B, m, n_err) on the error state, ``R`` (m, m), component ``names`` and the model's
    ``layout`` it reads its quantities through."""

    R: np.ndarray
    names: tuple[str, ...]
    layout: StateLayout

    @abstractmethod
    def h(self, x: np.ndarray, u: np.ndarray) -> np.ndarray: ...

    @abstractmethod
    def jacobian(self, x: np.ndarray, u: np.ndarray) -> np.ndarray: ...

    @property
    def groups(self) -> dict[str, tuple[str, ...]]:
        """Groups of the components (``names``) whose NIS the tables judge apart
        (:attr:`quadest.models.base.MeasurementModel.groups`); none by default: the whole
        measurement is one group."""
        return {}

    def select(self, runs: slice | np.ndarray) -> SensorModel:
        """The sensor bound to a subset of runs (a slice or index array; the same sensor unless it
        carries per-run values)."""
        return self

    def quantity(self, name: str, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Quantity ``name`` of the states ``x`` (:meth:`StateLayout.value`)."""
        return self.layout.value(name, x, u)

    def _zeros(self, x: np.ndarray) -> np.ndarray:
        return np.zeros((x.shape[0], self.R.shape[0], self.layout.n_err))

    def place(self, J: np.ndarray, rows: slice, name: str, D: np.ndarray, x: np.ndarray, u: np.ndarray) -> None:
        """Write ``D ∂q/∂δx`` into rows ``rows`` of ``J`` (B, m, n_err), ``D`` (B, r, d) or (r, d)
        the derivative of those rows with respect to quantity ``q = name`` (chain rule). Where
        the layout moves ``q`` one to one with error columns, ``D`` is written there directly
        (the other columns of those rows untouched); an input quantity adds nothing."""
        if name in self.layout.error:
            J[:, rows, self.layout.error[name]] = D
        elif name not in self.layout.inputs:
            J[:, rows] += D @ self.layout.jacobian(name, x, u)


class Sensor(ABC):
    """One further sensor (module docstring): subclass it, set the class attributes, implement
    :meth:`simulate` and :meth:`measurement_model`, and register it (a module of
    :mod:`quadest.sensors`, or the entry-point group ``quadest.sensors``).

    An instance holds one job's ``settings`` (an instance of ``Settings``) and ``context``; what
    :meth:`simulate` draws per run that the filters may know (a calibration) it keeps on the
    instance for :meth:`measurement_model`, which is called after it.
    """

    config_name: ClassVar[str]
    Settings: ClassVar[type]
    settings_key: ClassVar[str | None] = None
    streams: ClassVar[tuple[str, ...]] = ()
    measures: ClassVar[tuple[str, ...]] = ()

    def __init__(self, settings: Any, context: SensorContext) -> None:
        self.settings = settings
        self.context = context

    @classmethod
    def key(cls) -> str:
        """Where the settings live: ``settings_key``, else ``sensor.<config_name>``."""
        return cls.settings_key or f"sensor.{cls.config_name}"

    @classmethod
    def stream_names(cls) -> tuple[str, ...]:
        """The names of its random streams: ``streams``, else one named after the sensor."""
        return cls.streams or (cls.config_name,)

    @classmethod
    def validate(cls, settings: Any, key: str, sample_period: float) -> None:
        """Range checks of ``settings`` (found at ``key``), one :class:`ConfigError` naming the
        first bad key. The default checks ``rate`` (:func:`check_rate`) and ``noise_law`` if the
        settings have them; override to add yours (and call it)."""
        if hasattr(settings, "rate"):
            check_rate(f"{key}.rate", settings.rate, sample_period)
        if hasattr(settings, "noise_law"):
            check_noise_law(f"{key}.noise_law", settings.noise_law)

    @abstractmethod
    def simulate(self, truth: TrueMotion, streams: Mapping[str, list[np.random.Generator]]) -> SensorRecord:
        """The samples (B, K+1, m) of ``truth`` and their availability (K+1,), drawn from
        ``streams[name]`` (one generator per run) for each name of :meth:`stream_names` only."""

    @abstractmethod
    def measurement_model(self, layout: StateLayout) -> SensorModel:
        """The filters' model of this sensor on a model whose quantities are at ``layout``."""


def allowed_rates(sample_period: float, shown: int = 5) -> str:
    """The rates a sensor may have on a filter of step ``sample_period``, as an error's allowed
    values: the filter rate ``f = 1/sample_period`` divided by a whole number, the first ``shown``
    of them listed (100, 50, 33.3333, 25, 20, … Hz at f = 100 Hz)."""
    f = 1.0 / sample_period
    first = ", ".join(f"{f / k:g}" for k in range(1, shown + 1))
    return f"one of {first}, … Hz (it must divide the filter rate 1/sample_period = {f:g} Hz: {f:g}/k, k = 1, 2, …)"


def sample_stride(rate: float, sample_period: float, key: str) -> int:
    """Filter steps between two samples of a sensor at ``rate`` Hz; the rate must divide the
    filter rate ``1/sample_period`` and not exceed it, else a :class:`ConfigError` naming ``key``
    (the sensor's ``<settings key>.rate``) and :func:`allowed_rates`."""
    ratio = 1.0 / (rate * sample_period)
    stride = round(ratio)
    if stride < 1 or abs(ratio - stride) > 1e-9 * ratio:
        raise ConfigError(key, rate, allowed_rates(sample_period))
    return stride


def check_rate(key: str, rate: Any, sample_period: float) -> None:
    """``rate`` (Hz) must be > 0 and divide the filter rate; the error names ``key``."""
    require_positive(key, rate, "must be > 0 Hz")
    sample_stride(float(rate), sample_period, key)


def available_samples(rate: float, sample_period: float, samples: int, key: str) -> np.ndarray:
    """(samples,) bool: a sample every :func:`sample_stride` filter steps, from step 0; a rate
    that does not divide the filter rate is refused naming ``key``."""
    return np.arange(samples) % sample_stride(rate, sample_period, key) == 0


def sensor_problems(cls: Any) -> list[str]:
    """What keeps ``cls`` from being a usable sensor (empty when it is one)."""
    if not inspect.isclass(cls) or not issubclass(cls, Sensor):
        return [f"{cls!r} must subclass quadest.sensors.base.Sensor"]
    problems = []
    if inspect.isabstract(cls):
        problems.append(f"it does not implement {', '.join(sorted(cls.__abstractmethods__))}")
    if not isinstance(getattr(cls, "config_name", None), str):
        problems.append("it must set config_name")
    if not (isinstance(getattr(cls, "Settings", None), type) and dataclasses.is_dataclass(cls.Settings)):
        problems.append("its Settings must be a dataclass")
    unknown = sorted(set(getattr(cls, "measures", ())) - set(QUANTITIES))
    if unknown:
        problems.append(f"it measures unknown quantities {unknown}; known: {sorted(QUANTITIES)}")
    return problems
