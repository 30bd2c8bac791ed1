"""NEES per state group and NIS per measurement group the model declares, each judged against its
own χ² band (Bar-Shalom, Li & Kirubarajan 2001, §5.4.2).

The NEES of state group g is ``x̃_gᵀ (P_gg)⁻¹ x̃_g`` with the group's block of the covariance (the
marginal covariance of those states): χ²(n_g) for a consistent filter. The NIS of measurement
group g is ``ν_gᵀ (S_gg)⁻¹ ν_g`` with the group's block of the innovation covariance S: a
sub-vector of a Gaussian vector is Gaussian with the marginal covariance, so it is χ²(m_g) for a
consistent filter. A whole-state NEES (whole-measurement NIS) in the band can hide one group that
is optimistic and another that is pessimistic; per group they show.

The state groups are :attr:`quadest.models.base.FilterModel.state_groups`; the measurement groups
are the primary measurement's (:attr:`~quadest.models.base.FilterModel.measurement_groups`) and
each further sensor's (:attr:`~quadest.models.base.MeasurementModel.groups`: by default the whole
sensor, named after it; declared ones are named ``<sensor>_<group>``). A measurement group counts
only at the steps its measurement updated the filter (a sensor at its own rate), and its band
share is over those steps.

Columns per group: ``nees_<group>``, ``nis_<group>`` (per run, the time average over the steps
with a usable block) and ``nees_in_band_<group>``, ``nis_in_band_<group>`` (per estimator, the
share of steps whose run average lies in the 95 % band of χ²(group size),
:func:`quadest.metrics.consistency.fraction_inside`).
"""

from __future__ import annotations

import numpy as np

from quadest.metrics.base import BatchStart, Column, Metric, StepView
from quadest.metrics.consistency import fraction_inside
from quadest.models.base import FilterModel
from quadest.numerics import batched_cholesky, whiten


def marginal_mahalanobis_sq(vector: np.ndarray, factor: np.ndarray, index: list[int]) -> np.ndarray:
    """(B,) ``v_gᵀ (Σ_gg)⁻¹ v_g`` of the components ``index`` of ``vector`` (B, n) with their
    marginal covariance ``Σ_gg = (L Lᵀ)[index, index]`` of the lower factors ``factor`` (B, n, n);
    NaN where that block is not positive definite."""
    rows = factor[:, index, :]
    block = rows @ np.swapaxes(rows, -1, -2)
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        L = batched_cholesky(np.where(np.isfinite(block), block, 0.0))[0]
        L[~np.isfinite(block).all(axis=(-2, -1))] = np.nan
        return np.sum(whiten(L, vector[:, index]) ** 2, axis=-1)


def measurement_groups(model: FilterModel) -> dict[str, tuple[str | None, list[int]]]:
    """Every measurement group of ``model``: its name → (its measurement: ``None`` for the primary,
    else the sensor's name; the indices of its components). A component that is not one of its
    measurement's names, or a name that two groups share, is a ``ValueError``."""
    found: dict[str, tuple[str | None, list[int]]] = {}
    declared = [(group, None, tuple(model.measurement_names), c) for group, c in model.measurement_groups.items()]
    for sensor, measurement in model.sensors.items():
        own = measurement.groups or {"": measurement.names}
        for group, components in own.items():
            declared.append((f"{sensor}_{group}" if group else sensor, sensor, measurement.names, components))
    for name, sensor, names, components in declared:
        unknown = [c for c in components if c not in names]
        if unknown or name in found:
            why = f"components {unknown} are not among {names}" if unknown else "the name is taken"
            raise ValueError(f"measurement group {name!r} of model {model.name!r}: {why}")
        found[name] = (sensor, [names.index(c) for c in components])
    return found


class _GroupStreams:
    """One χ² statistic per group: per-run sums and counts, and per step the run average over the
    live runs where it was usable and whether the group was measured at all."""

    def __init__(self, batch: BatchStart, prefix: str, dofs: dict[str, int]) -> None:
        K1, B, G = batch.time.size, batch.runs, len(dofs)
        self.prefix, self.dofs = prefix, dofs
        self.sum, self.count = np.zeros((B, G)), np.zeros((B, G))
        self.mean_t, self.alive_t = np.full((K1, G), np.nan), np.zeros((K1, G))
        self.scheduled_t = np.zeros((K1, G), dtype=bool)

    def add(self, k: int, j: int, values: np.ndarray, alive: np.ndarray) -> None:
        """Group ``j``'s statistic (B,) at step ``k``; the runs of ``alive`` with a finite value count."""
        use = alive & np.isfinite(values)
        self.scheduled_t[k, j] = True
        self.sum[use, j] += values[use]
        self.count[use, j] += 1
        self.alive_t[k, j] = use.sum()
        if use.any():
            self.mean_t[k, j] = values[use].mean()

    def finish(self) -> dict[str, np.ndarray]:
        out = {}
        with np.errstate(invalid="ignore", divide="ignore"):
            for j, (group, dof) in enumerate(self.dofs.items()):
                out[f"{self.prefix}_{group}"] = self.sum[:, j] / self.count[:, j]
                out[f"{self.prefix}_in_band_{group}"] = fraction_inside(
                    self.mean_t[:, j], dof, self.alive_t[:, j], self.scheduled_t[:, j]
                )
        return out


class _StateStreams(_GroupStreams):
    def __init__(self, batch: BatchStart) -> None:
        model = batch.model
        self.groups = {g: [model.error_names.index(s) for s in states] for g, states in model.state_groups.items()}
        super().__init__(batch, "nees", {g: len(index) for g, index in self.groups.items()})

    def step(self, view: StepView) -> None:
        for j, index in enumerate(self.groups.values()):
            self.add(view.k, j, marginal_mahalanobis_sq(view.error, view.factor, index), view.alive)


class _MeasurementStreams(_GroupStreams):
    def __init__(self, batch: BatchStart) -> None:
        self.groups = measurement_groups(batch.model)
        super().__init__(batch, "nis", {g: len(index) for g, (_, index) in self.groups.items()})

    def step(self, view: StepView) -> None:
        for j, (sensor, index) in enumerate(self.groups.values()):
            if sensor in view.innovations:
                nu, factor = view.innovations[sensor]
                self.add(view.k, j, marginal_mahalanobis_sq(nu, factor, index), view.alive)


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

    def start(self, batch: BatchStart) -> _StateStreams | None:
        return _StateStreams(batch) if batch.model.state_groups else None


class GroupNIS(Metric):
    name = "group_nis"
    needs_truth = False

    def columns(self, model: FilterModel) -> tuple[Column, ...]:
        columns = []
        for group, (_, index) in measurement_groups(model).items():
            meaning = f"per-run mean NIS of the measurement group {group} ({len(index)} dof) over the steps it updated"
            columns.append(Column(f"nis_{group}", "run", meaning))
            share = f"share of its steps in the 95 % band of {group}"
            columns.append(Column(f"nis_in_band_{group}", "estimator", share))
        return tuple(columns)

    def start(self, batch: BatchStart) -> _MeasurementStreams | None:
        return _MeasurementStreams(batch) if measurement_groups(batch.model) else None
