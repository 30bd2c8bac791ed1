"""The replay job kind (``source`` set): a flight log's data, and the difference to the log's
reference where a simulation has errors.

A replay writes the files every job writes (docs/outputs.md), with three differences:

- the compared quantities are PX4's roll, pitch and yaw (ZYX Euler angles, degrees, wrapped to
  ±180°); ``quantity`` is ``difference to PX4`` and ``rmse`` is the RMS *difference* to the
  reference over the steps from ``source.warmup`` seconds on (the filters start from the first
  samples alone, PX4's filter had been running since boot);
- NEES and the PCRLB are left out (``null``/empty, with a note): both need the true state, and
  PX4's estimate is not one. NIS stays: it needs only the measurements;
- one "run": no Monte Carlo spread, so ``rmse_std`` is empty and the paired comparison has no
  test (fewer than two runs).

Figures: ``figures/attitude_vs_px4.png`` (roll, pitch, yaw of every filter and of PX4 against
time) and ``figures/difference_to_px4.png`` (the differences, the warm-up shaded).

An offline reference of our own: an estimator with a fixed-interval smoother (``smoother:
fixed_interval``, docs/smoothers.md) gives a row ``<label>+smoothed`` that uses the whole log. The
job then also writes ``difference_to_smoothed.csv`` and ``difference_to_smoothed.md``: the RMS
difference (degrees, over the same window) of every other row and of PX4's own estimate to each
smoothed row, that is how far each online filter is from the best estimate these measurements
allow under our models; and ``figures/difference_to_smoothed.png``. ``summary.json`` holds the
same numbers under ``difference_to_smoothed``.

Our filters' yaw is magnetic, PX4's true: every filter's estimate is turned by the log's
declination (:mod:`quadest.replay.declination`) before any comparison, and the saved estimates and
angles are the turned ones. The caption and ``summary.json`` (``declination``) say by how much and
where it came from.

Errors against the truth, where the log has one (SITL: ``vehicle_attitude_groundtruth``):
``truth_errors.csv`` (``estimator, state, unit, rms``), the RMS error in degrees over the compared
window of every row *and* of PX4's own estimate (``px4``), in roll, pitch, yaw and the attitude
error angle on SO(3) (:func:`quadest.models.attitude.attitude_errors_deg`); printed below the
table, in ``summary.json`` (``truth_errors``) and ``timeseries.npz`` (``ground_truth``,
``ground_truth_angles_deg``). Without a ground truth, the caption says so and no file is written.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from quadest.app.open_loop_job import OpenLoopJob
from quadest.app.pipeline import Finished, Report
from quadest.evaluation.captions import table_caption
from quadest.evaluation.formatting import markdown_table
from quadest.evaluation.job_tables import MetricTables, further_measures
from quadest.evaluation.metrics import estimator_overview, metric_rows, metric_summary, summarize
from quadest.evaluation.paired import paired_comparison
from quadest.metrics.quantiles import error_quantiles
from quadest.metrics.windows import windowed
from quadest.models.attitude import attitude_errors_deg
from quadest.montecarlo import MonteCarloData
from quadest.montecarlo.results import EstimatorResult
from quadest.numerics import quaternion as quat
from quadest.replay.data import PX4_ROW, ReplayData
from quadest.replay.declination import to_true_north
from quadest.replay.ulog import ATTITUDE_TRUTH, POSITION_TRUTH

ANGLES = ("roll", "pitch", "yaw")
QUANTITY = "difference to PX4"
ROWS = [(QUANTITY, state, "deg") for state in (*ANGLES, "attitude")]
"""The rows of a replay's tables: the Euler angles and the attitude difference as one rotation angle
on SO(3) (:func:`quadest.models.attitude.attitude_errors_deg`)."""
ROW_ORDER = [1, 2, 3, 0]
"""Where each of :data:`ROWS` is in :func:`~quadest.models.attitude.attitude_errors_deg`'s output."""
PX4 = "PX4 onboard estimate"
TRUTH_COLUMNS = ["estimator", "state", "unit", "rms"]
SMOOTHED = "+smoothed"
NOT_APPLICABLE = (
    "NEES and PCRLB are not reported: they need the true state, and a flight log has none "
    "(PX4's onboard estimate is a reference, not the truth)."
)


def euler_deg(x: np.ndarray) -> np.ndarray:
    """Roll, pitch, yaw (..., 3) in degrees of states (..., ≥4) whose first four entries are the
    body→earth quaternion."""
    return np.degrees(quat.to_euler(x[..., :4]))


def rms_difference(diff: np.ndarray, window: np.ndarray) -> np.ndarray:
    """RMS over the steps of ``window`` (3,); NaN if any of them is NaN."""
    return np.sqrt(np.mean(diff[window] ** 2, axis=0))


def _state_values(diffs: dict[str, np.ndarray], window: np.ndarray) -> dict[str, dict[str, np.ndarray]]:
    """Each estimator's per-state columns of ``metrics.csv`` over the rows :data:`ROWS`: the RMS
    difference and the quantiles of the absolute difference over ``window`` (one run)."""
    return {
        name: {
            "rmse": rms_difference(d, window)[None],
            **{k: v[None] for k, v in error_quantiles(d[window], 0).items()},
        }
        for name, d in diffs.items()
    }


def _windowed(diffs: dict[str, np.ndarray], time: np.ndarray, window: np.ndarray, settings) -> dict[str, dict]:
    """Each estimator's transient and steady-state RMS difference and its settling time over the
    steps of ``window`` (:func:`quadest.metrics.windows.windowed`; a diverged step counts no run)."""
    out = {}
    for name, d in diffs.items():
        kept = d[window]
        alive = np.isfinite(kept).all(axis=-1).astype(float)
        out[name] = windowed(time[window] - time[window][0], np.where(np.isfinite(kept), kept, 0.0) ** 2, alive,
                             settings)  # fmt: skip
    return out


def _printed(summary: pd.DataFrame) -> pd.DataFrame:
    """State × estimator, the RMS difference in degrees (``diverged`` where it did)."""
    text = summary.assign(
        cell=["diverged" if np.isnan(v) else f"{v:.3f}" for v in summary["rmse_mean"]],
        row=[f"{s} [{u}]" for s, u in zip(summary["state"], summary["unit"], strict=True)],
    )
    wide = text.pivot_table(index="row", columns="estimator", values="cell", aggfunc="first", sort=False)
    wide.columns.name = None
    return wide.reset_index().rename(columns={"row": "state"})


def offline_references(results: list[EstimatorResult]) -> list[EstimatorResult]:
    """The fixed-interval smoothed rows among ``results`` (``<label>+smoothed``), in order: each
    used the whole log, so it is an offline reference for the online rows."""
    return [res.smoothed for res in results if res.smoothed is not None and res.smoothed.name.endswith(SMOOTHED)]


def difference_to_smoothed(angles: dict[str, np.ndarray], references: list[str], window: np.ndarray) -> pd.DataFrame:
    """The RMS difference in degrees over ``window`` of every row of ``angles`` (name → roll,
    pitch, yaw (K, 3) in degrees; PX4's estimate included) to each reference row: one line per
    reference, other row and angle, the differences wrapped to ±180°."""
    lines = []
    for reference in references:
        for name, a in angles.items():
            if name == reference:
                continue
            diff = wrap_deg(a - angles[reference])
            for j, rms in enumerate(rms_difference(diff, window)):
                lines.append({"reference": reference, "estimator": name, "state": ANGLES[j], "unit": "deg",
                              "rms_difference": float(rms)})  # fmt: skip
    return pd.DataFrame(lines, columns=["reference", "estimator", "state", "unit", "rms_difference"])


def truth_errors(estimates: dict[str, np.ndarray], truth: np.ndarray, window: np.ndarray) -> pd.DataFrame:
    """The RMS error in degrees against ``truth`` (K+1, 4) over the steps of ``window`` where the
    truth is defined, of every state sequence (K+1, ≥ 4) of ``estimates`` (name → states whose
    first four entries are the body→NED quaternion): one line per name and state of :data:`ROWS`
    (roll, pitch, yaw, attitude angle); NaN where a row diverged."""
    compared = window & np.isfinite(truth).all(axis=-1)
    lines = []
    for name, states in estimates.items():
        errors = attitude_errors_deg(states, truth)[:, ROW_ORDER]
        rms = rms_difference(errors, compared) if compared.any() else np.full(len(ROWS), np.nan)
        lines += [{"estimator": name, "state": state, "unit": unit, "rms": float(value)}
                  for (_, state, unit), value in zip(ROWS, rms, strict=True)]  # fmt: skip
    return pd.DataFrame(lines, columns=TRUTH_COLUMNS)


def _truth_markdown(table: pd.DataFrame, data: MonteCarloData) -> str:
    """State × row, the RMS error against the ground truth in degrees."""
    wide = table.pivot_table(index="state", columns="estimator", values="rms", sort=False)
    wide.columns.name = None
    cells = wide.map(lambda v: "diverged" if np.isnan(v) else f"{v:.3f}").reset_index()
    start = data.time[0] + data.labels["warmup"]
    return (f"RMS error against the ground truth ({ATTITUDE_TRUTH}) of every filter and of PX4's estimate "
            f"({PX4_ROW}), degrees, from t = {start:g} s:\n\n{markdown_table(cells)}\n")  # fmt: skip


def truth_line(data: ReplayData) -> str:
    """The caption's line on the log's ground truth."""
    if data.ground_truth is not None:
        return f"Ground truth: {ATTITUDE_TRUTH}; errors against it in truth_errors.csv."
    if data.position_truth:
        return (f"The log has {POSITION_TRUTH} but no {ATTITUDE_TRUTH}: the attitude replay has no state to compare "
                "with it (no truth_errors.csv).")  # fmt: skip
    return f"The log has no ground truth ({ATTITUDE_TRUTH}): differences to PX4 only, no truth_errors.csv."


def wrap_deg(angle: np.ndarray) -> np.ndarray:
    """Angles in degrees wrapped to [−180, 180)."""
    return (angle + 180.0) % 360.0 - 180.0


def _difference_markdown(table: pd.DataFrame) -> str:
    """One block per reference: angle × row, the RMS difference in degrees."""
    blocks = []
    for reference, part in table.groupby("reference", sort=False):
        wide = part.pivot_table(index="state", columns="estimator", values="rms_difference", sort=False)
        wide.columns.name = None
        cells = wide.map(lambda v: "diverged" if np.isnan(v) else f"{v:.3f}").reset_index()
        blocks.append(f"RMS difference to {reference} [deg]\n\n{markdown_table(cells)}\n")
    return "\n".join(blocks)


def caption(data: ReplayData, results: list[EstimatorResult]) -> str:
    """The lines printed above the table (:func:`~quadest.evaluation.captions.table_caption`; a
    replay has no PCRLB column, :data:`NOT_APPLICABLE` says why), then the declination applied to
    our filters' yaw and whether the log has a ground truth."""
    lab = data.labels
    head = (
        f"RMS difference to the {lab['reference']} (vehicle_attitude) of {lab['log']}, degrees, from "
        f"t = {data.time[0] + lab['warmup']:g} s to {data.time[-1]:.1f} s (one log: no Monte Carlo spread)."
    )
    turned = f"Our filters' yaw turned from magnetic to true north by the declination: {data.declination.note}."
    return table_caption(head, lab["model"], results, NOT_APPLICABLE, (turned, truth_line(data)))


def plot_replay(data: MonteCarloData, angles: dict[str, np.ndarray], reference: np.ndarray, fig_dir: Path) -> None:
    """``attitude_vs_px4.png`` and ``difference_to_px4.png``."""
    t, warmup = data.time, data.labels["warmup"]
    fig, axes = plt.subplots(3, 1, figsize=(9, 7), sharex=True)
    for j, ax in enumerate(axes):
        ax.plot(t, reference[:, j], color="k", lw=2.2, label="PX4 onboard estimate")
        for name, a in angles.items():
            ax.plot(t, a[:, j], lw=1.0, label=name)
        ax.set_ylabel(f"{ANGLES[j]} [deg]")
    axes[0].legend(fontsize=8, ncol=len(angles) + 1, loc="upper right")
    axes[-1].set_xlabel("time since the log's first IMU sample [s]")
    _save(fig, f"{data.labels['log']}: attitude of our filters and of PX4", fig_dir / "attitude_vs_px4.png")
    fig, axes = plt.subplots(3, 1, figsize=(9, 7), sharex=True)
    for j, ax in enumerate(axes):
        for name, a in angles.items():
            ax.plot(t, wrap_deg(a[:, j] - reference[:, j]), lw=1.0, label=name)
        ax.axvspan(t[0], t[0] + warmup, color="0.85", zorder=0)
        ax.set_ylabel(f"{ANGLES[j]} diff. [deg]")
    axes[0].legend(fontsize=8, ncol=len(angles), loc="upper right")
    axes[-1].set_xlabel("time [s] (shaded: warm-up, not counted)")
    _save(fig, f"{data.labels['log']}: difference to PX4 (ours − PX4)", fig_dir / "difference_to_px4.png")


def plot_difference_to_smoothed(
    data: MonteCarloData, angles: dict[str, np.ndarray], reference: str, path: Path
) -> None:
    """Every other row's roll, pitch and yaw minus those of the offline ``reference`` row, PX4's
    estimate included, the warm-up shaded."""
    t, warmup = data.time, data.labels["warmup"]
    others = {name: a for name, a in angles.items() if name != reference}
    fig, axes = plt.subplots(3, 1, figsize=(9, 7), sharex=True)
    for j, ax in enumerate(axes):
        for name, a in others.items():
            style = {"color": "k", "lw": 1.8} if name == PX4 else {"lw": 1.0}
            ax.plot(t, wrap_deg(a[:, j] - angles[reference][:, j]), label=name, **style)
        ax.axvspan(t[0], t[0] + warmup, color="0.85", zorder=0)
        ax.set_ylabel(f"{ANGLES[j]} diff. [deg]")
    axes[0].legend(fontsize=8, ncol=len(others), loc="upper right")
    axes[-1].set_xlabel("time [s] (shaded: warm-up, not counted)")
    _save(fig, f"{data.labels['log']}: difference to the offline reference {reference}", path)


def _save(fig: plt.Figure, title: str, path: Path) -> None:
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


class ReplayJob(OpenLoopJob):
    """:class:`~quadest.app.pipeline.JobKind` of a flight-log replay: the open loop's data and work
    (the log is the data), its own report."""

    def report(self, finished: Finished) -> Report:
        """The tables, time series and summary fields of the module docstring; draws the figures."""
        cfg, data, params = self.experiment, finished.data, finished.rows.params
        results = finished.rows.results
        reference = data.truth[0]
        window = data.time >= data.time[0] + data.labels["warmup"]
        turned = {res.name: to_true_north(res.saved["estimate"], data.declination.deg) for res in results}
        # roll, pitch, yaw of the estimate minus PX4's, wrapped to ±180° (NaN once a run diverged)
        diffs = {name: attitude_errors_deg(est[0], reference)[:, ROW_ORDER] for name, est in turned.items()}
        labels = {**data.labels, "seed": int(cfg.seed), "runs": 1}
        table = metric_rows(results, data.model, params, labels, ROWS, _state_values(diffs, window))
        summary_table = summarize(table).assign(pooled_rmse=lambda s: s["rmse_mean"], pcrlb=np.nan)
        windows = _windowed(diffs, data.time, window, cfg.metrics)
        summary_table = summary_table.merge(
            metric_summary(results, table, data.model, cfg.metrics, windows), on=["estimator", "quantity", "state"]
        )
        with warnings.catch_warnings():  # NIS for filters without innovations
            warnings.simplefilter("ignore", RuntimeWarning)
            overview = estimator_overview(results, data.model, truth=False)
        printed = _printed(summary_table)
        paired = paired_comparison(table)
        tables = MetricTables(table, summary_table, overview, printed, paired, preamble=caption(data, results) + "\n\n",
                              further=further_measures(summary_table, overview))  # fmt: skip
        ref_angles = euler_deg(reference)
        angles = {name: euler_deg(est[0]) for name, est in turned.items()}
        arrays = {"time": data.time, "reference": reference, "reference_angles_deg": ref_angles}
        for res in results:
            arrays[f"{res.name}/estimate"] = turned[res.name]
            arrays[f"{res.name}/std"] = res.saved["std"]
            arrays[f"{res.name}/angles_deg"] = angles[res.name]
        offline = [res.name for res in offline_references(finished.results)]
        to_smoothed = difference_to_smoothed({**angles, PX4: ref_angles}, offline, window)
        to_truth = None
        if data.ground_truth is not None:
            to_truth = truth_errors({**{n: e[0] for n, e in turned.items()}, PX4_ROW: reference}, data.ground_truth,
                                    window)  # fmt: skip
            to_truth.to_csv(finished.out_dir / "truth_errors.csv", index=False)
            arrays["ground_truth"], arrays["ground_truth_angles_deg"] = data.ground_truth, euler_deg(data.ground_truth)
        if offline:
            to_smoothed.to_csv(finished.out_dir / "difference_to_smoothed.csv", index=False)
            (finished.out_dir / "difference_to_smoothed.md").write_text(_difference_markdown(to_smoothed))
        if cfg.output.figures:
            fig_dir = finished.out_dir / "figures"
            fig_dir.mkdir(exist_ok=True)
            plot_replay(data, angles, ref_angles, fig_dir)
            if offline:
                plot_difference_to_smoothed(data, {**angles, PX4: ref_angles}, offline[0],
                                            fig_dir / "difference_to_smoothed.png")  # fmt: skip
        fields = {
            "labels": {**data.labels, "seed": int(cfg.seed), "runs": 1, "duration": float(data.time[-1]),
                       "sample_period": float(cfg.sample_period)},
            "reference": data.labels["reference"],
            "compared_from": float(data.labels["warmup"]),
            "not_applicable": NOT_APPLICABLE,
            "state_names": list(ANGLES),
            "companion_names": [],
            "measurement_names": list(data.model.measurement_names),
            "declination": {"deg": data.declination.deg, "source": data.declination.source,
                            "note": data.declination.note},
            "ground_truth": truth_line(data),
            "truth_errors": None if to_truth is None else {
                name: dict(zip(part["state"], part["rms"], strict=True))
                for name, part in to_truth.groupby("estimator", sort=False)},
        }  # fmt: skip
        if offline:
            fields["difference_to_smoothed"] = {
                reference: {name: dict(zip(part["state"], part["rms_difference"], strict=True))
                            for name, part in by_reference.groupby("estimator", sort=False)}
                for reference, by_reference in to_smoothed.groupby("reference", sort=False)
            }  # fmt: skip
        after = [_truth_markdown(to_truth, data)] if to_truth is not None else []
        after += [_difference_markdown(to_smoothed)] if offline else []
        return Report(tables, fields, arrays, caption(data, results), "\n".join(after) or None)
