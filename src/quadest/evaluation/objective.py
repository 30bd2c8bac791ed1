"""The number a tuning sweep minimises (``objective`` in the config, docs/experiments.md).

For the estimator labelled ``objective.estimator``:

    J = mean over the filter states s of ln RMSE_s  +  nees_penalty · (1 − f_NEES)

where RMSE_s is the mean per-run RMSE of state s over the Monte Carlo runs and f_NEES the fraction of
time steps whose run-averaged NEES lies in its 95 % χ² band (Bar-Shalom, Li & Kirubarajan 2001,
§5.4.2; ``nees_in_band`` of summary.json). The mean of logarithms does not depend on the states'
units and a difference of 0.01 in it is a 1 % change of the geometric-mean RMSE, so
``nees_penalty = 1`` trades 10 % of time steps outside the band against 10 % of RMSE. A setting
under which any run diverges (or the estimator failed) scores ``inf``: RMSE over the surviving runs
would otherwise reward losing the hard runs.
"""

from __future__ import annotations

import math
from collections.abc import Collection
from dataclasses import dataclass

from quadest.errors import ConfigError


@dataclass
class ObjectiveConf:
    """The ``objective`` node (set by conf/hparams_search/): what a tuning sweep minimises, the mean
    log-RMSE of the filter states of ``estimator`` plus ``nees_penalty`` times the fraction of steps
    with NEES outside its 95 % band (module docstring). With ``estimator`` set, the task returns it
    (Hydra's Optuna sweeper reads that)."""

    estimator: str | None = None  # None: no objective
    nees_penalty: float = 1.0


def validate_objective(objective: ObjectiveConf, estimators: Collection[str]) -> None:
    """Raise :class:`ConfigError` if ``objective`` names an estimator that is not among the selected
    ``estimators`` (labels) or has a negative penalty; nothing to check when ``objective.estimator``
    is unset."""
    if objective.estimator is None:
        return
    if objective.estimator not in estimators:
        raise ConfigError(
            "objective.estimator", objective.estimator, f"one of the selected estimators {sorted(estimators)}"
        )
    if not objective.nees_penalty >= 0:
        raise ConfigError("objective.nees_penalty", objective.nees_penalty, "must be >= 0")


def objective_value(objective: ObjectiveConf, summary: dict) -> float:
    """J of the module docstring for ``objective.estimator`` in a job's ``summary`` (run_job's)."""
    est = summary["estimators"][objective.estimator]
    rmse = [r["mean"] for r in est["rmse"].values() if r["quantity"] == "filter"]
    if est["diverged"] or est["nees_in_band"] is None or any(v is None or v <= 0 for v in rmse):
        return math.inf
    log_rmse = sum(math.log(v) for v in rmse) / len(rmse)
    return log_rmse + float(objective.nees_penalty) * (1.0 - est["nees_in_band"])
