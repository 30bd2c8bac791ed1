"""Figures of one job: truth vs estimate, and estimation error with ±3σ bounds; and the figures a
model declares in ``extra_figures`` (:data:`EXTRA_FIGURES`)."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from quadest.evaluation.attitude_figures import plot_attitude_errors, plot_bias_estimates
from quadest.evaluation.pcrlb import pcrlb_is_bound
from quadest.metrics.consistency import chi2_band
from quadest.models.base import FilterModel
from quadest.montecarlo import MonteCarloData
from quadest.montecarlo.results import EstimatorResult


def _save(fig: plt.Figure, title: str, path: Path) -> Path:
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _grid(count: int) -> tuple[plt.Figure, np.ndarray]:
    """Up to three panels a row; a model with fewer states gets fewer, wider columns."""
    cols = min(3, count)
    rows = int(np.ceil(count / cols))
    width, height = {1: (9.0, 3.4), 2: (10.0, 2.6)}.get(cols, (4.2 * cols, 2.6))
    fig, axes = plt.subplots(rows, cols, figsize=(width, height * rows), sharex=True, squeeze=False)
    for ax in axes.flat[count:]:
        ax.set_visible(False)
    return fig, axes.ravel()


def plot_truth_vs_estimate(data: MonteCarloData, results: list[EstimatorResult], path: Path, run: int = 0) -> Path:
    """Every filter state and companion value of one run: truth and each estimator's estimate."""
    model = data.model
    names = list(model.state_names) + list(model.companion_names)
    units = list(model.state_units) + list(model.companion_units)
    truth = np.concatenate([data.truth[run], data.companion_truth[run]], axis=-1)
    fig, axes = _grid(len(names))
    for j, ax in enumerate(axes):
        if j >= len(names):
            break
        ax.plot(data.time, truth[:, j], color="k", lw=1.6, label="truth")
        for res in results:
            series = np.concatenate([res.saved["estimate"][run], res.saved["companion"][run]], axis=-1)
            ax.plot(data.time, series[:, j], lw=0.9, label=res.name)
        ax.set_ylabel(f"{names[j]} [{units[j]}]")
        ax.grid(alpha=0.3)
    for ax in list(axes)[-3:]:
        ax.set_xlabel("time [s]")
    next(iter(axes)).legend(fontsize=7, loc="best")
    names = ", ".join(r.name for r in results)
    return _save(fig, f"Truth vs estimate ({names}), run {run}", path)


def plot_errors(
    data: MonteCarloData, results: list[EstimatorResult], path: Path, bound: np.ndarray | None = None, run: int = 0
) -> Path:
    """Estimation error of each filter state with the filter's ±3σ, one row per estimator, and
    (dashed) ±3 standard deviations of the PCRLB, the floor no estimator's spread can go below."""
    model = data.model
    n = model.n_err
    width = max(2.6 * n, 8.0)  # a scalar model's one column is as wide as a page, its title readable
    fig, axes = plt.subplots(len(results), n, figsize=(width, 2.2 * len(results)), sharex=True, squeeze=False)
    for r, res in enumerate(results):
        err = model.boxminus(res.saved["estimate"][run], data.truth[run])
        sig = 3.0 * res.saved["std"][run]
        for j in range(n):
            ax = axes[r, j]
            ax.fill_between(data.time, -sig[:, j], sig[:, j], color="C0", alpha=0.2, lw=0, label="±3σ")
            ax.plot(data.time, err[:, j], color="C3", lw=0.7, label="error")
            if bound is not None:
                floor = 3.0 * np.sqrt(bound[:, j])
                ax.plot(data.time, floor, color="k", ls="--", lw=0.7, label="±3σ PCRLB")
                ax.plot(data.time, -floor, color="k", ls="--", lw=0.7)
            ax.grid(alpha=0.3)
            settled = data.time >= 0.1 * data.time[-1]  # scale to the run, not the first transient
            span = np.nanmax(np.concatenate([np.abs(err[settled, j]), sig[settled, j]]), initial=0.0)
            if np.isfinite(span) and span > 0:
                ax.set_ylim(-1.3 * span, 1.3 * span)
            if r == 0:
                ax.set_title(f"{model.error_names[j]} [{model.error_units[j]}]", fontsize=9)
            if j == 0:
                ax.set_ylabel(res.name)
            if r == len(results) - 1:
                ax.set_xlabel("time [s]")
    axes[0, 0].legend(fontsize=7)
    return _save(fig, f"Estimation error and ±3σ bounds, run {run}", path)


def plot_rmse_vs_time(data: MonteCarloData, results: list[EstimatorResult], bound: np.ndarray, path: Path) -> Path:
    """RMSE over the live runs at each step, per filter state and estimator, with the PCRLB floor."""
    model = data.model
    fig, axes = _grid(model.n_err)
    for j in range(model.n_err):
        ax = axes[j]
        for res in results:
            with np.errstate(invalid="ignore", divide="ignore"):
                rmse = np.sqrt(res.sq_error_t[:, j] / res.alive_t)
            ax.plot(data.time[1:], rmse[1:], lw=0.9, label=res.name)
        ax.plot(data.time, np.sqrt(bound[:, j]), color="k", ls="--", lw=1.2, label="PCRLB")
        ax.set_ylabel(f"RMSE {model.error_names[j]} [{model.error_units[j]}]")
        ax.set_yscale("log")
        ax.grid(alpha=0.3, which="both")
    for ax in axes[-min(3, model.n_err) :]:
        ax.set_xlabel("time [s]")
    axes[0].legend(fontsize=7)
    bound_here = pcrlb_is_bound(data.labels.get("model", ""), data.labels)
    what = "bound" if bound_here else "recursion (a reference, not a bound)"
    return _save(fig, f"RMSE over {data.truth.shape[0]} runs against the posterior Cramér-Rao {what}", path)


def plot_consistency(data: MonteCarloData, results: list[EstimatorResult], path: Path) -> Path:
    """Run-averaged NEES and NIS against time, each with its two-sided 95 % χ² band."""
    model = data.model
    fig, axes = plt.subplots(1, 2, figsize=(12, 3.6), sharex=True)
    for ax, key, dof, label in ((axes[0], "nees_mean_t", model.n_err, "NEES"), (axes[1], "nis_mean_t", model.m, "NIS")):
        for res in results:
            ax.plot(data.time[1:], getattr(res, key)[1:], lw=0.8, label=res.name)
        alive = results[0].alive_t if results else np.zeros(data.time.size)
        lo, hi = chi2_band(dof, np.where(alive > 0, alive, data.truth.shape[0]))
        ax.fill_between(data.time[1:], lo[1:], hi[1:], color="0.5", alpha=0.25, lw=0, label="95 % band")
        ax.axhline(dof, color="k", lw=0.8, ls=":")
        ax.set_yscale("log")
        ax.set_xlabel("time [s]")
        ax.set_ylabel(f"average {label} ({dof} dof)")
        ax.grid(alpha=0.3, which="both")
    axes[0].legend(fontsize=7)
    return _save(fig, f"Consistency over {data.truth.shape[0]} runs", path)


def _bias_estimates(model: FilterModel, series: Mapping[str, np.ndarray], path: Path) -> Path:
    """The model's ``bias_states`` (error-state names that are also state names) against the truth."""
    states = [model.state_names.index(name) for name in model.bias_states]
    return plot_bias_estimates(series, path, states, model.bias_states, [model.state_units[i] for i in states])


EXTRA_FIGURES: dict[str, Callable[[FilterModel, Mapping[str, np.ndarray], Path], Path]] = {
    "attitude_errors": lambda model, series, path: plot_attitude_errors(series, path),
    "bias_estimates": _bias_estimates,
}
"""Figures a model can ask for by name in ``extra_figures``: (model, saved series, path) → path.
The series are those of ``timeseries.npz`` (``time``, ``truth``, ``<estimator>/estimate``,
``<estimator>/std``)."""


def plot_extra_figures(model: FilterModel, series: Mapping[str, np.ndarray], fig_dir: Path) -> list[Path]:
    """Draw the model's ``extra_figures`` from the saved series into ``fig_dir/<name>.png``."""
    return [EXTRA_FIGURES[name](model, series, fig_dir / f"{name}.png") for name in model.extra_figures]
