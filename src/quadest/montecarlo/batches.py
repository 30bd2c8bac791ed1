"""One estimator's results on consecutive batches of runs, as the result on all of them.

A ``runs=auto`` job (docs/experiments.md) runs its estimators batch by batch: batch ``b`` holds
runs ``b·batch .. (b+1)·batch − 1``, from those runs' own streams
(:func:`quadest.montecarlo.streams.run_streams`), so the batches together are the runs of one
job with their total. :func:`concatenate_results` puts an estimator's batch results back
together, so that the job's tables, summary and figures are made as for any job.
"""

from __future__ import annotations

import numpy as np

from quadest.montecarlo.results import EstimatorResult

PER_RUN = (
    "sq_error_sum", "companion_sq_error_sum", "steps", "nees_sum", "nis_sum", "diverged", "diverged_step",
    "nees_steps", "derived_sq_error_sum",
)  # fmt: skip
"""Fields of :class:`EstimatorResult` with one entry per run (first axis): concatenated."""


def _weighted_mean_t(parts: list[EstimatorResult], field: str) -> np.ndarray:
    """A per-step average over the live runs, from the batches' averages weighted by their live
    runs; NaN where no batch has a value."""
    values = [getattr(p, field) for p in parts]
    weights = [np.where(np.isfinite(v), p.alive_t, 0.0) for v, p in zip(values, parts, strict=True)]
    total = sum(np.where(w > 0, v * w, 0.0) for v, w in zip(values, weights, strict=True))
    count = sum(weights)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(count > 0, total / count, np.nan)


def _per_run(result: EstimatorResult, name: str) -> np.ndarray:
    """A per-run field; ``nees_steps`` left unset means every counted step (``steps``)."""
    value = getattr(result, name)
    if value is None and name == "nees_steps":
        return result.steps
    return value


def concatenate_results(parts: list[EstimatorResult]) -> EstimatorResult:
    """The result of one estimator on the runs of ``parts`` (its results on consecutive batches,
    in order), as if it had run on all of them at once.

    Per-run arrays are concatenated and the run numbers of ``reasons`` shifted by the runs before
    their batch; per-step sums (``sq_error_t``, ``alive_t``) are added; per-step averages over the
    live runs (``nees_mean_t``, ``nis_mean_t``) are the averages weighted by each batch's live runs
    (exact for the NIS; for the NEES exact unless an estimator's covariance was singular at a step
    in a live run, the "cloud" estimators). The step time is the runs-weighted mean of the
    batches'. The saved series (and a result's own ``truth``) are the first batch's: they hold the
    first runs, as in a job that ran every run at once, if the saved runs fit in one batch.
    """
    first = parts[0]
    if len(parts) == 1:
        return first
    sizes = np.array([p.steps.shape[0] for p in parts])
    offsets = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    per_run = {name: np.concatenate([_per_run(p, name) for p in parts]) for name in PER_RUN}
    smoothed = None if any(p.smoothed is None for p in parts) else concatenate_results([p.smoothed for p in parts])
    return EstimatorResult(
        name=first.name,
        **per_run,
        nees_mean_t=_weighted_mean_t(parts, "nees_mean_t"),
        nis_mean_t=_weighted_mean_t(parts, "nis_mean_t"),
        sq_error_t=sum(p.sq_error_t for p in parts),
        alive_t=sum(p.alive_t for p in parts),
        reasons={int(i) + int(off): why for p, off in zip(parts, offsets, strict=True) for i, why in p.reasons.items()},
        step_time_us=float(np.average([p.step_time_us for p in parts], weights=sizes)),
        saved=first.saved,
        sensor_nis={
            s: tuple(np.concatenate([p.sensor_nis[s][j] for p in parts]) for j in (0, 1)) for s in first.sensor_nis
        },
        diagnostics={k: np.concatenate([p.diagnostics[k] for p in parts]) for k in first.diagnostics},
        truth=first.truth,
        companion_truth=first.companion_truth,
        smoothed=smoothed,
        flight=first.flight,
    )
