"""Attitude figures of a job whose model carries the attitude quaternion (``model=attitude``,
``model=ins``), and the settled attitude-error table of a finished job.

The job draws the figures for models that declare them (``extra_figures``,
:func:`quadest.evaluation.plotting.plot_extra_figures`) from its saved runs, and reports the RMSE of the
error angle and of the roll, pitch, yaw errors over all runs and steps as its ``derived`` rows
(:class:`quadest.models.attitude.AttitudeMetrics`):

- ``figures/attitude_errors.png``: the body-frame attitude error ``δθ = q̂ ⊟ q`` in degrees with
  the filter's ±3σ, and the error angle, run 0, one row per estimator;
- ``figures/bias_estimates.png``: the bias estimates against the truth, run 0.

The command ``python -m quadest.models.attitude_figures OUTPUT_DIR [--settle SECONDS]`` writes
``attitude_errors.csv`` into a job's output folder: per estimator, the RMS over the saved runs and
the steps after ``settle`` seconds of the error angle and the roll, pitch and yaw errors in
degrees (the steady state, without the initial transient the job's RMSE includes).
"""

from __future__ import annotations

import argparse
from collections.abc import Mapping, Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from quadest.models.attitude import ATTITUDE_ERROR_NAMES, attitude_errors_deg
from quadest.numerics import quaternion as quat

COLUMNS = tuple(f"{name}_deg" for name in ATTITUDE_ERROR_NAMES)


def _estimators(series: Mapping[str, np.ndarray], run: int = 0) -> list[str]:
    """The estimators with saved series up to ``run`` (a failed estimator saves none)."""
    return sorted(key.split("/")[0] for key in series if key.endswith("/estimate") and series[key].shape[0] > run)


def attitude_error_table(series: Mapping[str, np.ndarray], settle: float = 0.0) -> pd.DataFrame:
    """RMS attitude errors in degrees per estimator over the saved runs and the steps after
    ``settle`` seconds (runs that diverged are NaN in the series and left out)."""
    time, truth = series["time"], series["truth"]
    keep = time >= settle
    rows = []
    for name in _estimators(series):
        err = attitude_errors_deg(series[f"{name}/estimate"][:, keep], truth[:, keep])
        rms = np.sqrt(np.nanmean(err**2, axis=(0, 1)))
        rows.append({"estimator": name, **dict(zip(COLUMNS, rms, strict=True))})
    return pd.DataFrame(rows)


def _finish(fig: plt.Figure, axes: np.ndarray, title: str, path: Path) -> Path:
    axes[0, 0].legend(fontsize=7)
    for ax in axes[-1]:
        ax.set_xlabel("time [s]")
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_attitude_errors(series: Mapping[str, np.ndarray], path: Path, run: int = 0) -> Path:
    """Body-frame attitude error with ±3σ and the error angle, in degrees, one row per estimator
    (states whose first four components are the quaternion and first three error states δθ)."""
    time, truth = series["time"], series["truth"][run]
    names = _estimators(series, run)
    fig, axes = plt.subplots(len(names), 4, figsize=(13, 2.3 * len(names)), sharex=True, squeeze=False)
    for r, name in enumerate(names):
        est, std = series[f"{name}/estimate"][run], series[f"{name}/std"][run]
        dtheta = np.degrees(quat.boxminus(est[:, :4], truth[:, :4]))
        sigma = 3.0 * np.degrees(std[:, :3])
        for j, axis in enumerate("xyz"):
            ax = axes[r, j]
            ax.fill_between(time, -sigma[:, j], sigma[:, j], color="C0", alpha=0.2, lw=0, label="±3σ")
            ax.plot(time, dtheta[:, j], color="C3", lw=0.7, label="error")
            ax.set_title(f"δθ_{axis} [deg]" if r == 0 else "", fontsize=9)
            ax.grid(alpha=0.3)
        axes[r, 3].plot(time, np.linalg.norm(dtheta, axis=-1), color="k", lw=0.7)
        axes[r, 3].set_title("error angle [deg]" if r == 0 else "", fontsize=9)
        axes[r, 3].grid(alpha=0.3)
        axes[r, 0].set_ylabel(name)
    return _finish(fig, axes, f"Attitude error (body frame) and ±3σ, run {run}", path)


def plot_bias_estimates(
    series: Mapping[str, np.ndarray],
    path: Path,
    states: Sequence[int],
    names: Sequence[str],
    units: Sequence[str],
    run: int = 0,
) -> Path:
    """Estimates of the bias states (indices ``states`` of the state vector, with their names and
    units; rad/s shown in deg/s) of every estimator against the truth, three per row."""
    time, truth = series["time"], series["truth"][run]
    estimators = _estimators(series, run)
    rows = int(np.ceil(len(states) / 3))
    fig, axes = plt.subplots(rows, 3, figsize=(13, 2.75 * rows), sharex=True, squeeze=False)
    for ax, i, name, unit in zip(axes.flat, states, names, units, strict=False):
        scale, shown = (np.degrees(1.0), "deg/s") if unit == "rad/s" else (1.0, unit)
        ax.plot(time, scale * truth[:, i], color="k", lw=1.6, label="truth")
        for est in estimators:
            ax.plot(time, scale * series[f"{est}/estimate"][run][:, i], lw=0.9, label=est)
        ax.set_title(f"{name} [{shown}]", fontsize=9)
        ax.grid(alpha=0.3)
    for ax in axes.flat[len(states) :]:
        ax.set_visible(False)
    return _finish(fig, axes, f"Bias estimates against the truth, run {run}", path)


def write_attitude_report(out_dir: Path, settle: float = 0.0) -> pd.DataFrame:
    """Write ``attitude_errors.csv`` into a job's output folder (from its ``timeseries.npz``)."""
    out_dir = Path(out_dir)
    table = attitude_error_table(np.load(out_dir / "timeseries.npz"), settle)
    table.to_csv(out_dir / "attitude_errors.csv", index=False)
    return table


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out_dir", type=Path, help="output folder of a model=attitude or model=ins job")
    parser.add_argument("--settle", type=float, default=0.0, help="seconds left out of the RMS (default 0)")
    args = parser.parse_args(argv)
    print(write_attitude_report(args.out_dir, args.settle).round(4).to_string(index=False))


if __name__ == "__main__":
    main()
