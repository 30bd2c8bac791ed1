"""The paired comparison of one estimator across two jobs that differ in their data, not their filter.

A job's paired tables (``paired_comparison.csv``, ``paired_grouped.csv``) compare the estimators
*of one job*. A claim about the data (seed 004's 8 beacons against 3, a sensor grade, a scenario)
needs the same estimator run on two jobs. When both jobs have the same seed and the same runs,
run ``i`` of one and run ``i`` of the other draw the seed's per-run streams for run ``i`` (common
random numbers, :mod:`quadest.montecarlo.streams`): the per-run RMSEs are paired samples, as they
are between two estimators of one job, and pairing them removes the run-to-run scatter the two jobs
share. A stream whose draws the changed setting alters (the camera's, with another number of
beacons) is not shared; every other stream is.

The two jobs' rows of the estimator become one tidy table with the two jobs as two "estimators"
(named by their labels, the reference first), plus the 3-D position and velocity and the attitude
error angle where the job's model has them (:func:`quadest.aggregate.ranking.grouped_metrics`), and
:func:`quadest.evaluation.paired.paired_comparison` does the rest: runs paired by their index, a
run diverged in either job left out, ``job − reference`` per run with the Student-t interval of the
mean difference and Fieller's interval of the ratio (``rel_diff``: the difference in units of the
reference's mean RMSE), the raw two-sided Wilcoxon and t-test p and their Holm adjustment over the
table's states.

``python -m quadest.aggregate.cross_job REFERENCE_DIR JOB_DIR --estimator NAME --labels REF JOB --out DIR``
writes ``DIR/cross_job_comparison.csv`` (the columns of ``paired_comparison.csv``; ``pair`` is
``JOB - REF``) and ``DIR/cross_job_comparison.md``. It refuses with one line and exit status 2,
before comparing anything, two jobs whose seeds, run counts, runs or states differ, an estimator
missing from either, or two equal labels.
"""

from __future__ import annotations

import argparse
import shlex
import sys
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from quadest.aggregate.ranking import GROUPS, grouped_metrics, has_grouped_states
from quadest.evaluation.paired import paired_comparison

TIDY = ("estimator", "run", "state", "unit", "quantity", "rmse", "diverged")
"""The columns of a job's ``metrics.csv`` that the paired comparison reads."""
TABLE = "cross_job_comparison.csv"
REPORT = "cross_job_comparison.md"
SHOWN = (*GROUPS, "error_angle")
"""The states the Markdown shows when the jobs have them (all states otherwise); the CSV has every state."""


class CrossJobError(ValueError):
    """Two jobs that cannot be compared run by run (the message says why in one line)."""


@dataclass(frozen=True)
class Job:
    """One side of the comparison: its folder, its label and the estimator's rows of its ``metrics.csv``."""

    folder: Path
    label: str
    rows: pd.DataFrame


def read_job(folder: Path, estimator: str, label: str) -> Job:
    """The rows of ``estimator`` in ``folder/metrics.csv``; :class:`CrossJobError` when the file, a
    column it needs (:data:`TIDY`, ``seed``, ``runs``) or the estimator is missing."""
    path = folder / "metrics.csv"
    if not path.is_file():
        raise CrossJobError(f"{path} does not exist (a job's output folder holds metrics.csv)")
    metrics = pd.read_csv(path)
    missing = [c for c in (*TIDY, "seed", "runs") if c not in metrics.columns]
    if missing:
        raise CrossJobError(f"{path} has no column(s) {missing}")
    rows = metrics[metrics["estimator"] == estimator]
    if rows.empty:
        held = list(dict.fromkeys(metrics["estimator"]))
        raise CrossJobError(f"--estimator {estimator!r} is not in {path}; it holds {held}")
    return Job(folder, label, rows)


def check_paired(reference: Job, job: Job) -> None:
    """Refuse two jobs whose run ``i`` does not share its draws (seed, run count or run indices
    differ), whose states differ, or whose labels are equal."""
    if reference.label == job.label:
        raise CrossJobError(f"--labels must differ, both are {job.label!r}")
    for column, what in (("seed", "seeds"), ("runs", "run counts")):
        ours, theirs = (sorted(set(side.rows[column])) for side in (reference, job))
        if ours != theirs or len(ours) != 1:
            raise CrossJobError(
                f"the jobs' {what} differ ({column} {ours} in {reference.folder}, {theirs} in {job.folder}): "
                "run i of two jobs shares its draws only with the same seed and runs"
            )
    for column, what in (("run", "runs"), ("state", "states")):
        ours, theirs = (set(side.rows[column]) for side in (reference, job))
        if ours != theirs:
            odd = sorted(ours ^ theirs, key=str)
            raise CrossJobError(f"the jobs' {what} differ: {odd[:5]} in one of {reference.folder}, {job.folder} only")


def tidy(job: Job) -> pd.DataFrame:
    """The job's per-run RMSE table under its label, with the grouped states where its model has them
    (``error_angle`` is a state of the job already)."""
    parts = [job.rows[list(TIDY)]]
    if has_grouped_states(job.rows):
        grouped = grouped_metrics(job.rows)
        parts.append(grouped.loc[~grouped["state"].isin(job.rows["state"]), list(TIDY)])
    return pd.concat(parts, ignore_index=True).assign(estimator=job.label)


def cross_job_comparison(reference: Job, job: Job) -> pd.DataFrame:
    """The paired comparison ``job − reference`` of the estimator over their common runs (module
    docstring), one row per state; refuses jobs that are not paired (:func:`check_paired`)."""
    check_paired(reference, job)
    return paired_comparison(pd.concat([tidy(reference), tidy(job)], ignore_index=True))


def markdown(table: pd.DataFrame, reference: Job, job: Job, estimator: str, command: str) -> str:
    """The report: the two jobs, the pairing, and the difference per state (the grouped states when present)."""
    grouped = table.set_index("state").reindex([s for s in SHOWN if s in set(table["state"])]).reset_index()
    shown = grouped if len(grouped) else table
    seed, runs = (reference.rows[c].iloc[0] for c in ("seed", "runs"))  # equal in both jobs (check_paired)
    lines = [
        f"# {job.label} against {reference.label}: {estimator}, paired by run",
        "",
        f"`{command}`",
        "",
        f"{reference.label} (reference): `{reference.folder}`; {job.label}: `{job.folder}`. Seed {seed}, {runs} runs "
        "each: run i of the two jobs draws the seed's per-run streams for run i, so the per-run RMSEs are paired; "
        "a run diverged in either job is left out. Difference: "
        f"{job.label} − {reference.label}, per-run RMSE, in % of the mean RMSE of {reference.label}, "
        f"with Fieller's 95 % interval; p: two-sided Wilcoxon signed-rank, Holm-adjusted over the table's "
        f"{len(table)} states ({TABLE} has them all, with the raw p).",
        "",
        f"| state | unit | runs | mean RMSE {job.label} / {reference.label} "
        "| difference, % (95 % CI) | p Wilcoxon (Holm) |",
        "|---|---|---|---|---|---|",
    ]  # fmt: skip
    for _, r in shown.iterrows():
        rel, low, high = (100 * r[c] for c in ("rel_diff", "rel_ci_low", "rel_ci_high"))
        lines.append(
            f"| {r['state']} | {r['unit']} | {r['runs']} | {r['rmse_mean']:.4g} / {r['reference_rmse_mean']:.4g} "
            f"| {rel:+.3g} [{low:+.3g}, {high:+.3g}] | {r['p_wilcoxon_holm']:.2g} |"
        )
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m quadest.aggregate.cross_job",
        description="Paired comparison of one estimator across two jobs on the same seed and runs (JOB - REFERENCE).",
    )
    parser.add_argument("reference", type=Path, help="the reference job's folder (holds metrics.csv)")
    parser.add_argument("job", type=Path, help="the compared job's folder (holds metrics.csv)")
    parser.add_argument("--estimator", required=True, help="the estimator to compare (in both jobs' metrics.csv)")
    parser.add_argument("--labels", nargs=2, metavar=("REF", "JOB"), help="names of the two jobs (default: folders)")
    parser.add_argument("--out", type=Path, required=True, help="folder for cross_job_comparison.csv and .md")
    args = parser.parse_args(argv)
    labels = args.labels or [str(args.reference), str(args.job)]
    try:
        reference = read_job(args.reference, args.estimator, labels[0])
        job = read_job(args.job, args.estimator, labels[1])
        table = cross_job_comparison(reference, job)
    except CrossJobError as error:
        print(f"cross_job: error: {error}", file=sys.stderr)
        return 2
    words = ["python -m quadest.aggregate.cross_job", str(args.reference), str(args.job), "--estimator",
             args.estimator, "--labels", *labels, "--out", str(args.out)]  # fmt: skip
    command = " ".join(words[:1] + [shlex.quote(w) for w in words[1:]])
    args.out.mkdir(parents=True, exist_ok=True)
    table.to_csv(args.out / TABLE, index=False)
    (args.out / REPORT).write_text(markdown(table, reference, job, args.estimator, command), encoding="utf-8")
    print(f"cross_job: wrote {args.out / TABLE} and {args.out / REPORT}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
