"""NEES per state group the model declares (:attr:`quadest.models.base.FilterModel.state_groups`),
each judged against its own χ² band (Bar-Shalom, Li & Kirubarajan 2001, §5.4.2).

The NEES of group g is ``x̃_gᵀ (P_gg)⁻¹ x̃_g`` with the group's block of the covariance (the
marginal covariance of those states): χ²(n_g) for a consistent filter. A whole-state NEES in the
band can hide one group that is optimistic and another that is pessimistic; per group they show.
Columns per group: ``nees_<group>`` (per run, the time average over the steps 1..K with a usable
block) and ``nees_in_band_<group>`` (per estimator, the share of steps whose run average lies in
the 95 % band of χ²(n_g), :func:`quadest.metrics.consistency.fraction_inside`).
"""

from __future__ import annotations

import numpy as np

from quadest.metrics.base import BatchStart, Column, Metric, StepView
from quadest.metrics.consistency import fraction_inside
from quadest.models.base import FilterModel
from quadest.numerics import batched_cholesky, whiten


def group_nees(error: np.ndarray, factor: np.ndarray, index: list[int]) -> np.ndarray:
    """(B,) NEES of the states ``index`` with the marginal covariance ``(L Lᵀ)[index, index]``
    of the lower factors ``factor`` (B, n, n); NaN where that block is not positive definite."""
    rows = factor[:, index, :]
    block = rows @ np.swapaxes(rows, -1, -2)
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        L = batched_cholesky(np.where(np.isfinite(block), block, 0.0))[0]
        L[~np.isfinite(block).all(axis=(-2, -1))] = np.nan
        return np.sum(whiten(L, error[:, index]) ** 2, axis=-1)


class _Streams:
    def __init__(self, batch: BatchStart) -> None:
        model, K1, B = batch.model, batch.time.size, batch.runs
        self.groups = {g: [model.error_names.index(s) for s in states] for g, states in model.state_groups.items()}
        G = len(self.groups)
        self.sum, self.count = np.zeros((B, G)), np.zeros((B, G))
        self.mean_t, self.alive_t = np.full((K1, G), np.nan), np.zeros((K1, G))

    def step(self, view: StepView) -> None:
        for j, index in enumerate(self.groups.values()):
            nees = group_nees(view.error, view.factor, index)
            use = view.alive & np.isfinite(nees)
            self.sum[use, j] += nees[use]
            self.count[use, j] += 1
            self.alive_t[view.k, j] = use.sum()
            if use.any():
                self.mean_t[view.k, j] = nees[use].mean()

    def finish(self) -> dict[str, np.ndarray]:
        out = {}
        with np.errstate(invalid="ignore", divide="ignore"):
            for j, (group, index) in enumerate(self.groups.items()):
                out[f"nees_{group}"] = self.sum[:, j] / self.count[:, j]
                out[f"nees_in_band_{group}"] = fraction_inside(self.mean_t[:, j], len(index), self.alive_t[:, j])
        return out


class GroupNEES(Metric):
    name = "group_nees"

    def columns(self, model: FilterModel) -> tuple[Column, ...]:
        columns = []
        for group, states in model.state_groups.items():
            columns.append(
                Column(f"nees_{group}", "run", f"per-run mean NEES of the group {group} ({len(states)} dof)")
            )
            columns.append(Column(f"nees_in_band_{group}", "estimator", f"share of steps in the 95 % band of {group}"))
        return tuple(columns)

    def start(self, batch: BatchStart) -> _Streams | None:
        return _Streams(batch) if batch.model.state_groups else None
