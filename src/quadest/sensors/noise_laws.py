"""Laws of a sensor's white noise that the filters do not know about (the robust filters of seed 004).

Every law is the nominal Gaussian draw ``σ·n`` (``n`` standard normal) times a per-sample
multiplier ``s`` drawn after it from the same generator:

- ``gaussian``: ``s = 1`` and no further draw, so the noise is bit-identical to ``σ·n``;
- ``contaminated``: ``s = √f`` with probability ε, independently per element, else 1. The density
  is the contaminated Gaussian ``(1 − ε)·N(0, σ²) + ε·N(0, f·σ²)`` of Huber (1964) and seed 004
  (their eq. 63: ε = 0.1, f = 5); the total variance is ``σ²(1 − ε + ε·f)``;
- ``student_t``: ``s = √((ν − 2)/w)`` with ``w ~ χ²(ν)``, so ``σ·n·s`` is Student-t with ν degrees
  of freedom scaled to the **nominal variance** σ² (needs ν > 2). The filters' R is then the true
  second moment, and a difference between filters comes from the heavy tails alone, not from a
  mis-stated variance;
- ``bursts``: outlier bursts in time. At each sample a burst starts with probability ``rate`` (a
  per-sample rate: the expected number of bursts per second is ``rate / T``) and lasts ``length``
  samples (bursts that overlap merge); during a burst ``s = √f`` on every axis of the sample.

Because ``n`` is drawn first, the sweeps over ε, f, ν or the burst settings scale the same normal
draws (common random numbers across cells, as well as across estimators, which share the data).
The filters keep the nominal R = σ².
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from quadest.config.ranges import require_positive
from quadest.errors import ConfigError

NOISE_LAWS = ("gaussian", "contaminated", "student_t", "bursts")


@dataclass
class NoiseLaw:
    """A noise law and its settings; also the config schema of ``sensor.<triad>.noise_law``.

    Only the settings of the selected ``kind`` are read: ``epsilon`` and ``variance_factor`` for
    ``contaminated`` (defaults: seed 004's ε = 0.1 and 5×), ``dof`` for ``student_t``, ``rate``
    (per sample), ``length`` (samples) and ``variance_factor`` for ``bursts``.
    """

    kind: str = "gaussian"
    epsilon: float = 0.1
    variance_factor: float = 5.0
    dof: float = 4.0
    rate: float = 0.01
    length: int = 10


def noise_law_from_config(law: NoiseLaw | None) -> NoiseLaw:
    """A copy of the ``sensor.<triad>.noise_law`` settings ``law`` (``None``: Gaussian)."""
    if law is None:
        return NoiseLaw()
    return NoiseLaw(**{k: getattr(law, k) for k in NoiseLaw.__dataclass_fields__})


def check_noise_law(key: str, law) -> None:
    """Raise a one-line :class:`ConfigError` naming ``key.<setting>`` if ``law`` (a :class:`NoiseLaw`
    or its config node) is out of range; only the settings of the selected kind are checked."""
    if law.kind not in NOISE_LAWS:
        raise ConfigError(f"{key}.kind", law.kind, f"one of {list(NOISE_LAWS)}")
    if law.kind in ("contaminated", "bursts"):
        require_positive(f"{key}.variance_factor", law.variance_factor, "must be > 0 (outlier variance / nominal)")
    if law.kind == "contaminated" and not (isinstance(law.epsilon, int | float) and 0.0 <= law.epsilon <= 1.0):
        raise ConfigError(f"{key}.epsilon", law.epsilon, "must lie in [0, 1] (the contamination probability)")
    if law.kind == "student_t" and not (isinstance(law.dof, int | float) and law.dof > 2.0):
        raise ConfigError(f"{key}.dof", law.dof, "must be > 2 (the draws are scaled to the nominal variance)")
    if law.kind == "bursts":
        if not (isinstance(law.rate, int | float) and 0.0 <= law.rate <= 1.0):
            raise ConfigError(f"{key}.rate", law.rate, "must lie in [0, 1] (burst starts per sample)")
        if not (isinstance(law.length, int) and law.length >= 1):
            raise ConfigError(f"{key}.length", law.length, "must be an integer >= 1 (samples per burst)")


def burst_mask(rng: np.random.Generator, samples: int, rate: float, length: int) -> np.ndarray:
    """Boolean (samples,): inside a burst. A burst starts at each sample with probability ``rate``
    and covers that sample and the ``length − 1`` after it."""
    starts = rng.random(samples) < rate
    return np.convolve(starts, np.ones(length, dtype=int))[:samples] > 0


def noise_multiplier(law: NoiseLaw, rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray | float:
    """The multiplier ``s`` of the nominal draw (module docstring); the first axis of ``shape`` is time."""
    if law.kind == "gaussian":
        return 1.0
    if law.kind == "contaminated":
        return np.where(rng.random(shape) < law.epsilon, np.sqrt(law.variance_factor), 1.0)
    if law.kind == "student_t":
        return np.sqrt((law.dof - 2.0) / rng.chisquare(law.dof, shape))
    if law.kind == "bursts":
        inside = burst_mask(rng, shape[0], law.rate, law.length).reshape((shape[0],) + (1,) * (len(shape) - 1))
        return np.broadcast_to(np.where(inside, np.sqrt(law.variance_factor), 1.0), shape)
    raise ConfigError("noise_law.kind", law.kind, f"one of {list(NOISE_LAWS)}")


def draw_noise(law: NoiseLaw, rng: np.random.Generator, shape: tuple[int, ...], std: float) -> np.ndarray:
    """Noise of nominal standard deviation ``std`` under ``law``, from the run's generator ``rng``:
    ``std · n · s`` with ``n`` standard normal of ``shape`` drawn first (module docstring)."""
    return std * rng.standard_normal(shape) * noise_multiplier(law, rng, shape)
