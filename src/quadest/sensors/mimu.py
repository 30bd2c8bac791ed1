"""MIMU triad error model with the five error classes of thesis §5.3.1 (seed 000).

Per triad (gyro or accelerometer), for a true input ``y`` (body frame):

    ỹ = (I + S + S± ⊙ sgn(y) + M) y + b0 + b(t) + n

- ``S``: diagonal scale-factor error; ``S±``: scale-factor asymmetry, acting with the sign of
  each axis input; ``M``: zero-diagonal cross-coupling (installation misalignment);
- ``b0``: constant drift (turn-on bias); ``b(t)``: random drift, a random walk with
  ``σ_bd = σ_bc √T`` per sample; ``n``: white noise with ``σ_d = σ_c / √T``, Gaussian unless a
  :class:`~quadest.sensors.noise_laws.NoiseLaw` says otherwise (the filters keep ``σ_d``).

The deterministic errors (S, S±, M, b0) are drawn once per Monte Carlo run, with the given
numbers as one-sigma values. ``error_scale`` multiplies every error term.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from quadest.sensors.noise_laws import NoiseLaw, draw_noise


@dataclass
class TriadSpec:
    """One-sigma error levels of a triad (continuous-time densities for the random terms).

    Also the config schema of ``sensor.accel`` and ``sensor.gyro``."""

    scale_factor: float = 0.0
    asymmetry: float = 0.0
    cross_coupling: float = 0.0
    bias: float = 0.0
    bias_random_walk: float = 0.0
    white_noise: float = 0.0

    def scaled(self, factor: float) -> TriadSpec:
        return TriadSpec(*(factor * getattr(self, name) for name in self.__dataclass_fields__))

    def white_noise_std(self, sample_period: float) -> float:
        """Discrete white-noise standard deviation ``σ_c / √T``."""
        return self.white_noise / np.sqrt(sample_period)


@dataclass
class TriadErrors:
    """Deterministic errors of a batch of triads: ``matrix = I + S + M`` (B, 3, 3),
    ``asymmetry`` (B, 3) and ``bias`` (B, 3)."""

    matrix: np.ndarray
    asymmetry: np.ndarray
    bias: np.ndarray

    @classmethod
    def nominal(cls, batch: int) -> TriadErrors:
        """Error-free triads (what a filter that ignores the errors assumes)."""
        return cls(np.broadcast_to(np.eye(3), (batch, 3, 3)).copy(), np.zeros((batch, 3)), np.zeros((batch, 3)))

    def __getitem__(self, idx) -> TriadErrors:
        return TriadErrors(self.matrix[idx], self.asymmetry[idx], self.bias[idx])

    def apply(self, y: np.ndarray) -> np.ndarray:
        """Deterministic part ``(I + S + S± ⊙ sgn(y) + M) y + b0`` for ``y`` (B, ..., 3).

        ``sgn(y) y`` is written with the sign of the real part so that the complex step works.
        """
        shape = (slice(None),) + (None,) * (y.ndim - 2)
        a, b = self.asymmetry[shape], self.bias[shape]
        if y.ndim == 3:
            linear = y @ np.swapaxes(self.matrix, -1, -2)
        else:
            linear = np.einsum("b...ij,b...j->b...i", self.matrix[(*shape, slice(None))], y)
        return linear + a * np.sign(y.real) * y + b

    def jacobian(self, y: np.ndarray) -> np.ndarray:
        """``∂ apply / ∂y`` (B, 3, 3) at ``y`` (B, 3): ``I + S + M + diag(S± ⊙ sgn(y))``."""
        return self.matrix + np.einsum("bi,ij->bij", self.asymmetry * np.sign(y.real), np.eye(3))

    def correction(self, raw: np.ndarray) -> np.ndarray:
        """``C`` (B, K, 3, 3): the inverse of ``I + S + M + diag(S± ⊙ sgn(raw))`` for bias-free
        samples ``raw`` (B, K, 3), so ``C raw`` undoes the matrix errors. The sign is taken from
        the sample: where it differs from the input's, the input is near zero and so is the
        asymmetry term."""
        M = self.matrix[:, None] + np.einsum("bki,ij->bkij", self.asymmetry[:, None] * np.sign(raw.real), np.eye(3))
        return np.linalg.inv(M)


def draw_triad_errors(spec: TriadSpec, rngs: list[np.random.Generator]) -> TriadErrors:
    """Draw the deterministic errors once per run, one generator per run."""
    mats, asym, bias = [], [], []
    off_diagonal = ~np.eye(3, dtype=bool)
    for rng in rngs:
        M = np.eye(3) + np.diag(spec.scale_factor * rng.standard_normal(3))
        M[off_diagonal] += spec.cross_coupling * rng.standard_normal(6)
        mats.append(M)
        asym.append(spec.asymmetry * rng.standard_normal(3))
        bias.append(spec.bias * rng.standard_normal(3))
    return TriadErrors(np.array(mats), np.array(asym), np.array(bias))


def measure_triad(
    spec: TriadSpec,
    errors: TriadErrors,
    y_true: np.ndarray,
    sample_period: float,
    rngs: list[np.random.Generator],
    noise_law: NoiseLaw | None = None,
) -> np.ndarray:
    """Measured triad (B, K+1, 3): deterministic errors, random-walk drift and white noise drawn
    under ``noise_law`` (default Gaussian)."""
    law = NoiseLaw() if noise_law is None else noise_law
    B, K1, _ = y_true.shape
    walk = np.empty((B, K1, 3))
    noise = np.empty((B, K1, 3))
    step = spec.bias_random_walk * np.sqrt(sample_period)
    sigma = spec.white_noise_std(sample_period)
    for i, rng in enumerate(rngs):
        increments = step * rng.standard_normal((K1, 3))
        increments[0] = 0.0
        walk[i] = np.cumsum(increments, axis=0)
        noise[i] = draw_noise(law, rng, (K1, 3), sigma)
    return errors.apply(y_true) + walk + noise
