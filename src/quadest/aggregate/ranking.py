"""Seed 004's ranking (HHCF > HF > HCKF > EKF) tested on a job (``experiment=seed004_landing``,
docs/seed004-landing.md).

Per run, the 3-D position and velocity RMSE (root of the sum of the three axes' mean squares) and
the attitude error angle's RMSE (``error_angle``), then the job's own paired comparison
(:func:`quadest.paired.paired_comparison` on these three grouped states: paired bootstrap CI,
Wilcoxon, Holm over every pair of the job's estimators × the three states) for each step of the
ranking. A step *holds* when its Holm-corrected Wilcoxon p is below 0.05 and the better-ranked
filter has the smaller RMSE, is *reversed* when p < 0.05 the other way, and is *not shown*
otherwise.

``python -m quadest.aggregate.ranking JOB_DIR`` writes ``JOB_DIR/ranking.md`` and prints it.
"""

from __future__ import annotations

import sys

import numpy as np
import pandas as pd

from quadest.aggregate.job_cli import read_job_metrics
from quadest.paired import paired_comparison

GROUPS = {"position_3d": ("x", "y", "z"), "velocity_3d": ("vx", "vy", "vz")}
STEPS = (
    ("hhcf", "hf"), ("hf", "hckf"), ("hckf", "mekf"),  # seed 004's ranking, step by step
    ("hhcf", "hckf"), ("hf", "mekf"), ("hckf", "ckf"), ("srukf_huber", "srukf"),  # other steps and Huber vs parent
)  # fmt: skip


def grouped_metrics(metrics: pd.DataFrame) -> pd.DataFrame:
    """One row per estimator × run × {position_3d, velocity_3d, error_angle}."""
    keep = ["estimator", "run", "diverged"]
    wide = metrics.pivot_table(index=["estimator", "run"], columns="state", values="rmse", sort=False)
    diverged = metrics.groupby(["estimator", "run"], sort=False)["diverged"].any()
    rows = []
    for state, axes in GROUPS.items():
        rows.append(pd.DataFrame({"state": state, "rmse": np.sqrt((wide[list(axes)] ** 2).sum(axis=1))}))
    rows.append(pd.DataFrame({"state": "error_angle", "rmse": wide["error_angle"]}))
    out = pd.concat(rows).reset_index().merge(diverged.reset_index(), on=["estimator", "run"])
    out["unit"] = out["state"].map({"position_3d": "m", "velocity_3d": "m/s", "error_angle": "deg"})
    out["quantity"] = "filter"
    return out[keep[:2] + ["state", "unit", "quantity", "rmse", "diverged"]]


def ranking_lines(metrics: pd.DataFrame) -> list[str]:
    """The Markdown table of every step of :data:`STEPS` whose two estimators are in ``metrics``
    (a job's ``metrics.csv``), one row per step and grouped state."""
    names = list(dict.fromkeys(metrics["estimator"]))
    table = paired_comparison(grouped_metrics(metrics), seed=int(metrics["seed"].iloc[0]))
    lines = [
        "| claim | state | runs | better − worse, % of the earlier estimator's RMSE (95 % CI) "
        "| p Wilcoxon (Holm) | holds? |",
        "|---|---|---|---|---|---|",
    ]
    for better, worse in STEPS:
        if better not in names or worse not in names:
            continue
        ref, est = sorted((better, worse), key=names.index)
        sign = 1.0 if est == better else -1.0
        for _, r in table[(table["estimator"] == est) & (table["reference"] == ref)].iterrows():
            rel, lo, hi = (sign * 100 * r[c] for c in ("rel_diff", "rel_ci_low", "rel_ci_high"))
            lo, hi = min(lo, hi), max(lo, hi)
            p = r["p_wilcoxon_holm"]
            verdict = "not shown" if not p < 0.05 else ("yes" if rel < 0 else "no (reversed)")
            claim = f"| {better} > {worse} | {r['state']} | {r['runs']} |"
            lines.append(f"{claim} {rel:+.2f} % [{lo:+.2f}, {hi:+.2f}] | {p:.2g} | {verdict} |")
    return lines


def main(argv: list[str] | None = None) -> int:
    job = read_job_metrics(
        "ranking", "Seed 004's ranking (HHCF > HF > HCKF > EKF) tested on a job's paired comparison.", argv
    )
    if job is None:
        return 2
    job_dir, metrics = job
    lines = ranking_lines(metrics)
    (job_dir / "ranking.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
