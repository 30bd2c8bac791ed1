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

from quadest.evaluation.consistency import fraction_inside
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
    model = data.model
    columns = parameter_columns(estimator_params)
    frames = []
    for res in results:
        B = res.rmse.shape[0]
        params = estimator_params.get(res.name, {})
        blocks = [
            ("filter", model.error_names, model.error_units, res.rmse),
            ("derived", model.derived_error_names, model.derived_error_units, res.derived_rmse),
            ("companion", model.companion_names, model.companion_units, res.companion_rmse),
        ]
        for quantity, names, units, values in blocks:
            for j, (state, unit) in enumerate(zip(names, units, strict=True)):
                frame = pd.DataFrame(
                    {
                        "estimator": res.name,
                        "kind": params.get("kind", res.name),
                        "run": np.arange(B),
                        "state": state,
                        "unit": unit,
                        "quantity": quantity,
                        "rmse": values[:, j],
                        "diverged": res.diverged,
                        "diverged_step": res.diverged_step,
                        "failure_reason": [res.reasons.get(i, "") for i in range(B)],
                        "mean_nees": res.mean_nees,
                        "mean_nis": res.mean_nis,
                        "step_time_us": res.step_time_us,
                    }
                )
                for p in columns:
                    value = params.get(p, np.nan)
                    frame[p] = str(value) if isinstance(value, list | tuple | dict) else value
                for key, per_run in res.diagnostics.items():
                    frame[key] = per_run
                frames.append(frame)
    table = pd.concat(frames, ignore_index=True)
    for key, value in {**data.labels, **run_labels}.items():
        table[key] = value
    return table


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


def estimator_overview(results: list[EstimatorResult], n: int, m: int) -> pd.DataFrame:
    """Per estimator: diverged runs, average NEES (n dof) and NIS (m dof) over runs and time, the
    fraction of time steps whose run-averaged NEES and NIS lie in the 95 % χ² band, and the time
    per step."""
    rows = []
    for res in results:
        alive = (~res.diverged).any()
        rows.append(
            {
                "estimator": res.name,
                "diverged": int(res.diverged.sum()),
                "runs": int(res.diverged.size),
                "mean_nees": float(np.nanmean(res.mean_nees)) if alive else np.nan,
                "nees_dof": n,
                "nees_in_band": fraction_inside(res.nees_mean_t, n, res.alive_t),
                "mean_nis": float(np.nanmean(res.mean_nis)) if alive else np.nan,
                "nis_dof": m,
                "nis_in_band": fraction_inside(res.nis_mean_t, m, res.alive_t),
                "step_time_us": res.step_time_us,
            }
        )
    return pd.DataFrame(rows)


CONVERGENCE_FRACTION = 0.5
"""A bias has converged once the RMS of its error over the runs stays below this fraction of its
prior standard deviation (the error halved relative to what the filter started from)."""
FINAL_FRACTION = 0.1
"""The last fraction of the steps over which the final RMS of :func:`convergence_table` is taken."""


def convergence_time(time: np.ndarray, rms: np.ndarray, threshold: float) -> float:
    """The first time ``time[k]`` from which ``rms[k:]`` stays below ``threshold``: ``time[0]``
    if it never exceeds it, NaN if its last value does not lie below (NaN values count as not
    below: no run alive)."""
    below = rms < threshold
    if not below[-1]:
        return float("nan")
    above = np.flatnonzero(~below)
    return float(time[above[-1] + 1] if above.size else time[0])


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
