"""Metrics tables of one job: the tidy per-run table and the per-state summary.

RMSE convention: for each run and state, ``RMSE = sqrt(mean over steps 1..K of error²)``; the
summary reports the mean and standard deviation of these per-run values over the runs that did
not diverge (not the pooled ``sqrt`` of the mean squared error over all runs).

Rows of three quantities: ``filter`` (the error state ``estimate ⊟ truth``, the components the
NEES uses), ``derived`` (errors of quantities computed from the state that a model declares,
:meth:`~quadest.models.base.FilterModel.derived_errors`: the attitude models' error angle and
roll, pitch, yaw errors in degrees) and ``companion`` (values integrated outside the filter).

Bias convergence time (:func:`convergence_table`, for models that declare ``bias_states``): the
first time after which the RMS over runs of a bias state's error stays below
:data:`CONVERGENCE_FRACTION` of its prior standard deviation (docs/attitude.md).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from quadest.metrics.base import AGGREGATES, state_rows
from quadest.metrics.registry import all_metrics
from quadest.metrics.settings import MetricsConf
from quadest.metrics.windows import convergence_time
from quadest.models.base import FilterModel
from quadest.montecarlo import MonteCarloData
from quadest.montecarlo.results import EstimatorResult


def parameter_columns(estimator_params: dict[str, dict]) -> list[str]:
    """The union of the estimators' parameter names (their ``Params`` fields as configured, in
    order of first appearance), so ``cdkf.h`` or ``pf.particles`` tabulate like ``alpha``."""
    return list(dict.fromkeys(k for p in estimator_params.values() for k in p if k != "kind"))


def tidy_metrics(
    results: list[EstimatorResult],
    data: MonteCarloData,
    estimator_params: dict[str, dict],
    run_labels: dict,
) -> pd.DataFrame:
    """One row per estimator × run × state (filter states, derived errors, companion values)."""
    return metric_rows(results, data.model, estimator_params, {**data.labels, **run_labels})


def metric_rows(
    results: list[EstimatorResult],
    model: FilterModel,
    estimator_params: dict[str, dict],
    labels: dict,
    rows: list[tuple[str, str, str]] | None = None,
    state_values: dict[str, dict[str, np.ndarray]] | None = None,
) -> pd.DataFrame:
    """``metrics.csv`` of every job kind: one row per estimator × run × row of ``rows``
    ((quantity, state, unit); by default the model's state table,
    :func:`quadest.metrics.base.state_rows`), the columns every metric declares
    (:func:`quadest.metrics.registry.all_metrics`, in order; the estimators' parameter columns
    after the time per step), the state's group (``model.state_groups``) and ``labels``.

    ``state_values`` (estimator → column → (B, len(rows))) replaces the per-state columns of a job
    whose rows are not the model's state table (a flight-log replay); the columns of metrics that
    need the true state are then empty."""
    own_rows = rows is None
    rows = state_rows(model) if own_rows else rows
    group_of = {s: g for g, states in model.state_groups.items() for s in states}
    columns = parameter_columns(estimator_params)
    frames = []
    for res in results:
        B, R = res.diverged.shape[0], len(rows)
        params = estimator_params.get(res.name, {})
        frame = {
            "estimator": res.name,
            "kind": params.get("kind", res.name),
            "run": np.tile(np.arange(B), R),
            "state": np.repeat([s for _, s, _ in rows], B),
            "unit": np.repeat([u for _, _, u in rows], B),
            "quantity": np.repeat([q for q, _, _ in rows], B),
        }
        for metric in all_metrics():
            if metric.name == "diagnostics":
                for p in columns:
                    value = params.get(p, np.nan)
                    frame[p] = str(value) if isinstance(value, list | tuple | dict) else value
            declared = {c.name: c.per for c in metric.columns(model)}
            replaced = None if own_rows else (state_values or {}).get(res.name, {})
            for name, value in metric.values(res, model).items():
                per = declared.get(name, "run")
                if replaced is not None and per == "state":
                    value = replaced.get(name, np.full((B, R), np.nan))
                elif replaced is not None and metric.needs_truth:
                    value = {"state": np.full((B, R), np.nan), "run": np.full(B, np.nan)}.get(per, np.nan)
                frame[name] = _expand(value, per, B, R)
        frame["group"] = np.repeat([group_of.get(s, "") if q == "filter" else "" for q, s, _ in rows], B)
        frames.append(pd.DataFrame(frame))
    table = pd.concat(frames, ignore_index=True)
    for key, value in labels.items():
        table[key] = value
    return table


def _expand(value, per: str, B: int, R: int):
    """A column's values as one per row of ``metric_rows``' frame (state-major, runs within)."""
    if per == "state":
        return np.asarray(value).T.ravel()
    if per == "run":
        value = np.asarray(value) if not isinstance(value, list) else np.array(value, dtype=object)
        return np.tile(value, R)
    return value


def metric_summary(
    results: list[EstimatorResult],
    table: pd.DataFrame,
    model: FilterModel,
    settings: MetricsConf,
    custom: dict[str, dict[str, np.ndarray]] | None = None,
) -> pd.DataFrame:
    """The metrics' columns of ``rmse_summary.csv`` per estimator, quantity and state: each
    per-state column of ``table`` reduced over the runs that did not diverge by its declared
    aggregate, and the columns a metric computes itself (:meth:`quadest.metrics.base.Metric.summary`;
    ``custom``: estimator → column → (R,) values for rows that are not the model's), and the state's
    ``group``."""
    keys = ["estimator", "quantity", "state"]
    ok = table[~table["diverged"].astype(bool)]
    out = table[[*keys, "group"]].drop_duplicates(keys).reset_index(drop=True)
    for metric in all_metrics():
        for column in metric.columns(model):
            if column.per != "state" or column.name == "rmse":  # rmse: summarize's statistics
                continue
            reduce = AGGREGATES[column.aggregate]
            stats = ok.groupby(keys, sort=False)[column.name].agg(lambda v, f=reduce: _finite(f, v.to_numpy(float)))
            out = out.merge(stats.rename(column.name).reset_index(), on=keys, how="left")
        extra = metric.summary_columns(model)
        if not extra:
            continue
        parts = []
        for res in results:
            part = out.loc[out["estimator"] == res.name, keys].copy()
            values = (custom or {}).get(res.name) if custom is not None else metric.summary(res, model, settings)
            for name in extra:
                part[name] = values[name] if values is not None and name in values else np.nan
            parts.append(part)
        out = out.merge(pd.concat(parts), on=keys, how="left")
    return out


def _finite(reduce, values: np.ndarray) -> float:
    values = values[np.isfinite(values)]
    return float(reduce(values)) if values.size else np.nan


def summarize(table: pd.DataFrame) -> pd.DataFrame:
    """Per estimator and state: mean and std of the per-run RMSE over non-diverged runs, the mean
    of the per-run MSE (the UNGM benchmark's metric), and the number of diverged runs."""
    ok = table[~table["diverged"]].assign(mse=lambda t: t["rmse"] ** 2)
    stats = ok.groupby(["estimator", "quantity", "state", "unit"], sort=False).agg(
        rmse_mean=("rmse", "mean"), rmse_std=("rmse", "std"), mse_mean=("mse", "mean"), runs=("rmse", "count")
    )
    diverged = (
        table[table["diverged"]]
        .groupby(["estimator", "quantity", "state", "unit"], sort=False)["run"]
        .nunique()
        .rename("diverged")
    )
    out = stats.join(diverged, how="outer").reset_index()
    out["diverged"] = out["diverged"].fillna(0).astype(int)
    out["runs"] = out["runs"].fillna(0).astype(int)
    order = table[["estimator", "quantity", "state"]].drop_duplicates().reset_index(drop=True)
    return order.merge(out, on=["estimator", "quantity", "state"], how="left")


def floor_table(results: list[EstimatorResult], data: MonteCarloData, bound: np.ndarray) -> pd.DataFrame:
    """Per estimator and filter state: the pooled RMSE over runs and steps 1..K
    (``sqrt`` of the mean squared error over the live runs) and the PCRLB floor
    ``sqrt(mean_k diag J_k⁻¹)``. The bound limits the pooled MSE, so that is the column to set
    against it (a mean of per-run RMSEs can sit slightly below it by Jensen's inequality)."""
    floor = np.sqrt(bound[1:].mean(axis=0))
    rows = []
    for res in results:
        live = res.alive_t[1:].sum()
        with np.errstate(invalid="ignore", divide="ignore"):
            pooled = np.sqrt(res.sq_error_t[1:].sum(axis=0) / live) if live else np.full(floor.shape, np.nan)
        for j, state in enumerate(data.model.error_names):
            rows.append(
                {
                    "estimator": res.name,
                    "quantity": "filter",
                    "state": state,
                    "pooled_rmse": pooled[j],
                    "pcrlb": floor[j],
                }
            )
    return pd.DataFrame(rows)


NOT_A_STATE = {"derived": "derived quantity", "companion": "companion value"}


def bound_cell(quantity: str, floor: float, left_out: bool) -> str:
    """The PCRLB cell of the printed table: the floor, or why there is none (a row that is not a
    filter state, named by its quantity; a bound the job left out, its caption says why; a variance that is negative or
    not finite, which the covariance-form recursion of :mod:`quadest.evaluation.pcrlb` does not
    produce beyond round-off, and which is flagged, not hidden)."""
    if quantity != "filter":
        return f"n/a: {NOT_A_STATE.get(quantity, quantity)}"
    if np.isfinite(floor):
        return f"{floor:.4g}"
    return "left out (caption)" if left_out else "invalid: negative or non-finite variance"


def rmse_table(summary: pd.DataFrame) -> pd.DataFrame:
    """The printed table: one row per state, one column per estimator, ``mean ± std``, and the
    PCRLB floor of each filter state (:func:`bound_cell`)."""
    text = summary.assign(
        cell=[
            "diverged" if np.isnan(m) else f"{m:.4g} ± {s:.2g}"
            for m, s in zip(summary["rmse_mean"], summary["rmse_std"].fillna(0.0), strict=True)
        ],
        row=[f"{s} [{u}]" for s, u in zip(summary["state"], summary["unit"], strict=True)],
    )
    wide = text.pivot_table(index=["quantity", "row"], columns="estimator", values="cell", aggfunc="first", sort=False)
    wide.columns.name = None
    if "pcrlb" in summary:
        floors = text.drop_duplicates("row").set_index(["quantity", "row"])["pcrlb"].reindex(wide.index)
        left_out = not np.isfinite(floors[wide.index.get_level_values("quantity") == "filter"]).any()
        wide["PCRLB"] = [bound_cell(quantity, value, left_out) for (quantity, _), value in floors.items()]
    return wide.reset_index().drop(columns="quantity").rename(columns={"row": "state"})


def estimator_overview(results: list[EstimatorResult], model: FilterModel, truth: bool = True) -> pd.DataFrame:
    """Per estimator: every metric's overview entries (:meth:`quadest.metrics.base.Metric.overview`):
    diverged runs, average NEES (n_err dof) and NIS (m dof) over runs and time, the fraction of time
    steps whose run-averaged NEES and NIS lie in the 95 % χ² band, the time per step and the further
    metrics' per-estimator values. Without ``truth`` (a flight log) the metrics that need the true
    state are left out."""
    rows = []
    for res in results:
        row = {"estimator": res.name}
        for metric in all_metrics():
            if truth or not metric.needs_truth:
                row.update(metric.overview(res, model))
        rows.append(row)
    return pd.DataFrame(rows)


CONVERGENCE_FRACTION = 0.5
"""A bias has converged once the RMS of its error over the runs stays below this fraction of its
prior standard deviation (the error halved relative to what the filter started from)."""
FINAL_FRACTION = 0.1
"""The last fraction of the steps over which the final RMS of :func:`convergence_table` is taken."""


def convergence_table(
    results: list[EstimatorResult], data: MonteCarloData, fraction: float = CONVERGENCE_FRACTION
) -> pd.DataFrame:
    """Per estimator and bias state (``data.model.bias_states``): the prior standard deviation
    ``sqrt(P0_jj)``, the threshold ``fraction`` × prior σ, the convergence time (s after the
    start; :func:`convergence_time` of the RMS over the runs alive at each step 1..K, from
    ``sq_error_t`` and ``alive_t``; NaN when the RMS does not end below the threshold), and the
    final RMS over the last :data:`FINAL_FRACTION` of the steps, also relative to the prior σ."""
    model = data.model
    time = data.time[1:] - data.time[0]
    tail = slice(-max(1, round(FINAL_FRACTION * time.size)), None)
    rows = []
    for res in results:
        for state in model.bias_states:
            j = model.error_names.index(state)
            prior = float(np.sqrt(np.mean(data.P0[..., j, j])))  # per-run P0: the RMS of the prior σ
            with np.errstate(invalid="ignore", divide="ignore"):
                rms = np.sqrt(res.sq_error_t[1:, j] / res.alive_t[1:])
                final = float(np.sqrt(res.sq_error_t[1:][tail, j].sum() / res.alive_t[1:][tail].sum()))
            rows.append(
                {
                    "estimator": res.name,
                    "state": state,
                    "unit": model.error_units[j],
                    "prior_std": prior,
                    "threshold": fraction * prior,
                    "convergence_time_s": convergence_time(time, rms, fraction * prior),
                    "final_rms": final,
                    "final_over_prior": final / prior,
                }
            )
    return pd.DataFrame(rows)
