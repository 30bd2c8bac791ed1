"""Trajectory errors of a finished ``model=ins`` job against its truth: the ATE after SE(3) and
4-DoF alignment and the RPE over travelled distances (:mod:`quadest.metrics.trajectory`,
docs/metrics.md), per estimator and saved run, from ``timeseries.npz``.

The command ``python -m quadest.evaluation.trajectory_errors OUTPUT_DIR [--distances D ...]``
writes ``trajectory_errors.csv`` into the job's folder and prints it: one row per estimator, saved
run and measure (``ate_se3``, ``ate_4dof``, ``rpe``), with ``distance_m`` (the RPE's
sub-trajectory length; empty for the ATE), ``pairs`` (the poses or pairs compared), and the RMS
``position_m`` and ``rotation_deg`` over them. The poses are samples 1..K (sample 0 is the
filters' start, not scored); a run that diverged (NaN in its series) is left out. Its main use is a
recorded flight against its reference (docs/euroc.md), where the alignment removes what no
inertial estimator can know (the origin and, with 4-DoF, the heading).
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from quadest.metrics.trajectory import absolute_error, relative_errors

INS_STATE = 16
"""The INS state ``[q (4), p (3), v (3), b_g (3), b_a (3)]`` (:mod:`quadest.models.ins`)."""
DEFAULT_DISTANCES = (1.0, 5.0, 10.0)


def _estimators(series: Mapping[str, np.ndarray]) -> list[str]:
    return sorted(key.split("/")[0] for key in series if key.endswith("/estimate"))


def trajectory_error_table(series: Mapping[str, np.ndarray], distances: Sequence[float]) -> pd.DataFrame:
    """The rows of ``trajectory_errors.csv`` (module docstring) from a job's saved series.

    Raises:
        ValueError: the truth is not the INS state (16 columns).
    """
    truth = series["truth"]
    if truth.shape[-1] != INS_STATE:
        raise ValueError(f"the truth has {truth.shape[-1]} columns, not the INS state's {INS_STATE} (model=ins)")
    rows = []
    for name in _estimators(series):
        estimate = series[f"{name}/estimate"]
        for run in range(estimate.shape[0]):
            est, ref = estimate[run, 1:], truth[run, 1:]
            if not (np.all(np.isfinite(est)) and np.all(np.isfinite(ref))):
                continue
            base = {"estimator": name, "run": run}
            for kind in ("se3", "4dof"):
                ate = absolute_error(est[:, 4:7], est[:, 0:4], ref[:, 4:7], ref[:, 0:4], kind)
                rows.append(
                    {**base, "measure": f"ate_{kind}", "distance_m": np.nan, "pairs": len(est),
                     "position_m": ate.position_rmse, "rotation_deg": np.degrees(ate.rotation_rmse)}
                )  # fmt: skip
            for rpe in relative_errors(est[:, 4:7], est[:, 0:4], ref[:, 4:7], ref[:, 0:4], distances):
                rms = [np.sqrt(np.mean(e**2)) if e.size else np.nan for e in (rpe.translation, rpe.rotation)]
                rows.append(
                    {**base, "measure": "rpe", "distance_m": rpe.distance, "pairs": len(rpe.pairs),
                     "position_m": rms[0], "rotation_deg": np.degrees(rms[1])}
                )  # fmt: skip
    return pd.DataFrame(
        rows, columns=["estimator", "run", "measure", "distance_m", "pairs", "position_m", "rotation_deg"]
    )


def write_trajectory_errors(out_dir: Path, distances: Sequence[float] = DEFAULT_DISTANCES) -> pd.DataFrame:
    """Write ``out_dir/trajectory_errors.csv`` from ``out_dir/timeseries.npz`` and return the table."""
    with np.load(out_dir / "timeseries.npz") as npz:
        series = {key: npz[key] for key in npz.files}
    table = trajectory_error_table(series, distances)
    table.to_csv(out_dir / "trajectory_errors.csv", index=False)
    return table


def _refuse(message: str) -> None:
    """One line on stderr and exit status 2 (bad input), as the ``quadest`` command."""
    print(f"trajectory_errors: {message}", file=sys.stderr)
    sys.exit(2)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out_dir", type=Path, help="output folder of a model=ins job")
    parser.add_argument(
        "--distances",
        type=float,
        nargs="+",
        default=list(DEFAULT_DISTANCES),
        help="RPE lengths in metres (default 1 5 10)",
    )
    args = parser.parse_args(argv)
    if not (args.out_dir / "timeseries.npz").is_file():
        _refuse(f"{args.out_dir / 'timeseries.npz'} is missing (give the output folder of a job)")
    if any(d <= 0 for d in args.distances):
        _refuse(f"--distances={args.distances} is invalid: lengths > 0 in metres")
    try:
        table = write_trajectory_errors(args.out_dir, args.distances)
    except ValueError as exc:
        _refuse(str(exc))
    print(table.round(6).to_string(index=False))


if __name__ == "__main__":
    main()
