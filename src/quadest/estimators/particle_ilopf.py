"""Improved linear-optimisation particle filter of seed 001 (``estimator=ilopf``).

Li Yuansong & Liang Jinming (2015), "基于ILOPF的四旋翼姿态估计算法设计与实现" (Design and
implementation of ILOPF in attitude estimation of quadrotor), Fire Control & Command Control
40(9):167–171 (seed 001), §2.2–2.3: the EKPF (:mod:`quadest.estimators.particle_ekpf`) with a
modified resampling. At every resampling:

1. split the particles by the weight threshold ``ω_Thr`` into a *copy* group (``w ≥ ω_Thr``) and
   a *discard* group (``0 < w < ω_Thr``), and normalise the weights of each group;
2. for each of the N new particles draw ``x_a`` from the copy group (roulette wheel, or the
   configured ``resampling`` scheme) and ``x_s`` from the discard group (roulette wheel);
3. combine them, seed 001 eq. (8): ``x_new = x_a + ρ (x_s − x_a)`` with a random coefficient ρ.

Eq. (8) itself is lost from the seed text, which says only that it replaces the classic
linear-optimisation coefficient ``L = (N w)^(−1/m)`` (its eq. 6, m the state dimension) by a
random number written ``randn``. Our reconstruction keeps the classic form and draws ρ from a
configurable law (``coefficient``): ``normal`` (ρ ~ N(0, scale²), the literal reading of
``randn``; the default), ``uniform`` (ρ ~ U(0, scale)) or ``classic`` (ρ = (N w_a)^(−1/n), no
randomness). ``ω_Thr = threshold / N`` (its eq. 7 is lost too; 1/N is the weight at which a
particle expects one copy). A new particle keeps the EKF covariance ``P_i`` of its ``x_a``. When a
run's discard group is empty (or its copy group, possible for threshold > 1), its new particles
are drawn from all particles (plain resampling).

docs/particle-filters.md records these choices.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from quadest.estimators.params import ranged
from quadest.estimators.particle import gather_particles, one_of, particle_constraints
from quadest.estimators.particle_ekpf import EKPF, EKPFParams
from quadest.models.base import FilterModel
from quadest.numerics.resampling import resample

COEFFICIENT_LAWS = ("normal", "uniform", "classic")


@dataclass
class ILOPFParams(EKPFParams):
    """Configuration of ``estimator=ilopf``: the EKPF's plus the combination step's."""

    kind: str = "ilopf"
    resampling: str = "multinomial"
    threshold: float = ranged(1.0, "omega_Thr * N: the copy group has w >= threshold / N", gt=0.0)
    coefficient: str = "normal"
    coefficient_scale: float = ranged(1.0, "standard deviation (normal) or upper end (uniform) of rho", gt=0.0)

    @staticmethod
    def constraints(values: Mapping[str, Any], n: int) -> list[tuple[str, Any, str]]:
        """The shared particle-filter choices plus ``coefficient``, checked before any work."""
        problems = particle_constraints(values)
        if "coefficient" in values and values["coefficient"] not in COEFFICIENT_LAWS:
            problems.append(("coefficient", values["coefficient"], f"one of {list(COEFFICIENT_LAWS)}"))
        return problems


class ILOPF(EKPF):
    """EKPF with seed 001's combination resampling (see the module docstring).

    Args:
        model: the filter model, bound to a batch of B runs.
        threshold: ``ω_Thr·N`` (> 0): particles with weight ≥ threshold/N form the copy group.
        coefficient: law of ρ, ``normal``, ``uniform`` or ``classic``.
        coefficient_scale: the standard deviation (``normal``) or upper end (``uniform``) of ρ.
        **options: the EKPF's options (:class:`~quadest.estimators.particle_ekpf.EKPF`).
    """

    config_name = "ilopf"
    Params = ILOPFParams

    def __init__(
        self,
        model: FilterModel,
        threshold: float = 1.0,
        coefficient: str = "normal",
        coefficient_scale: float = 1.0,
        resampling: str = "multinomial",
        **options,
    ) -> None:
        super().__init__(model, resampling=resampling, **options)
        one_of("coefficient", coefficient, COEFFICIENT_LAWS)
        self.threshold, self.coefficient = float(threshold), coefficient
        self.coefficient_scale = float(coefficient_scale)

    def _coefficients(self, rngs: list[np.random.Generator], w_a: np.ndarray) -> np.ndarray:
        """ρ (R, N) for the new particles (``w_a``: the weights of their copy-group parents)."""
        if self.coefficient == "classic":
            return (self.N * w_a) ** (-1.0 / self.model.n)
        draw = (
            (lambda rng: rng.standard_normal(self.N))
            if self.coefficient == "normal"
            else (lambda rng: rng.random(self.N))
        )
        return self.coefficient_scale * np.stack([draw(rng) for rng in rngs])

    def redraw(self, w: np.ndarray, runs: np.ndarray) -> None:
        """Seed 001 §2.2: copy and discard groups, one roulette draw from each, eq. (8)."""
        copy = w >= self.threshold / self.N
        copy |= ~copy.any(axis=1, keepdims=True) & (w > 0)  # threshold > 1 can empty it: resample plainly
        discard = (w > 0) & ~copy
        a = resample(self.resampling, np.where(copy, w, 0.0), self.rngs, runs)
        has_discard = discard.any(axis=1)
        s = resample(
            "multinomial", np.where(discard, w, 0.0) + np.where(has_discard[:, None], 0.0, copy), self.rngs, runs
        )
        rngs = [self.rngs[i] for i in runs]
        rho = np.where(has_discard[:, None], self._coefficients(rngs, np.take_along_axis(w, a, axis=1)), 0.0)
        x = self.x[runs]
        x_a, x_s = gather_particles(x, a), gather_particles(x, s)
        self.x[runs] = x_a + rho[..., None] * (x_s - x_a)
        self.carry(runs, a)
