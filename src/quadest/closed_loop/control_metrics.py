"""How well the vehicle flew: tracking error per axis, step-response figures, control effort.

All metrics are computed on the **true** state of each flight (never on what the controller was
fed), per run; a crashed run has NaN metrics and its crash reason instead.

Step response of one step event (reference from ``y0`` to ``y1`` at ``t0``, up to the next step on
that axis or the end of the run), with ``r(t) = (y(t) − y0) / (y1 − y0)`` (Ogata, *Modern Control
Engineering*, 5th ed., §5-3, transient-response specifications):

- overshoot (%): ``100 · max(0, max r − 1)``, the maximum over the transient window (the
  ``transient_window`` seconds after ``t0``; without one, over the whole interval to the next step,
  where late noise peaks count as overshoot);
- peak error after the transient (%, only with a transient window): ``100 · max |r − 1|`` from
  ``t0 + transient_window`` to the end of the interval, the largest deviation once the step has
  been taken (seed 003's "maximum error 1.8°, 45 %");
- settling time (s): from ``t0`` to the first sample after which ``|r − 1| ≤ band`` holds to the
  end of the transient window (``band`` = 2 %; without a transient window, to the end of the
  interval); NaN when the response is outside the band at the window's last sample (not settled);
- steady-state error (%): ``100 · |mean r − 1|`` over the last ``steady_window`` seconds of the
  window;
- rise time (s): the 10–90 % rise time (Ogata §5-3, ``t_r`` for overdamped responses), from the
  first time ``r`` reaches 0.1 to the first time it reaches 0.9 within the transient window, each
  crossing interpolated linearly between the two samples around it; NaN when ``r`` never reaches 0.9
  there.

Tracking RMSE per channel over the whole run: roll, pitch, yaw and altitude in attitude mode,
x, y, altitude and yaw in position mode. Control effort: RMS over time of the commanded rotor
speeds' deviation from hover (rad/s); command rate: RMS of the commanded rotor speeds' change per
second (rad/s²), which measures the chatter that noisy feedback puts on the motors.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from quadest.evaluation.intervals import mean_and_half_width
from quadest.quadrotor.kinematics import wrap_angle

AXES = ("roll", "pitch", "yaw")


@dataclass(frozen=True)
class StepEvent:
    """One commanded step: attitude ``axis`` (0 roll, 1 pitch, 2 yaw) from ``start_value`` to
    ``target`` (rad) at ``time``; its response is scored until ``end_time``."""

    time: float
    axis: int
    start_value: float
    target: float
    end_time: float

    @property
    def label(self) -> str:
        return f"{AXES[self.axis]} {np.rad2deg(self.start_value):g}->{np.rad2deg(self.target):g} deg at {self.time:g} s"


def step_events(steps: list[list[float]], duration: float) -> list[StepEvent]:
    """The step events of an ``attitude_steps`` list ``[time_s, axis, angle_deg]``: every step
    before ``duration`` that changes its axis's reference, each scored until the next step on that
    axis (or ``duration``)."""
    ordered = sorted(steps, key=lambda s: s[0])
    events, current = [], np.zeros(3)
    for i, (start, axis, target_deg) in enumerate(ordered):
        a, target = int(axis), float(np.deg2rad(target_deg))
        later = [s[0] for s in ordered[i + 1 :] if int(s[1]) == a]
        if target != current[a] and start < duration:
            events.append(StepEvent(float(start), a, float(current[a]), target, min([*later, duration])))
        current[a] = target
    return events


RISE_LEVELS = (0.1, 0.9)
"""The fractions of the step between which the rise time is measured (10–90 %)."""


def first_crossing(t: np.ndarray, r: np.ndarray, level: float) -> np.ndarray:
    """Per row of ``r`` (B, K) sampled at ``t`` (K,): the first time ``r`` reaches ``level``,
    interpolated linearly between the last sample below it and the first at or above it (``t[0]``
    when the first sample already is); NaN when no sample reaches it."""
    reached = r >= level
    k = np.argmax(reached, axis=1)
    prev = np.maximum(k - 1, 0)
    rows = np.arange(r.shape[0])
    r0, r1 = r[rows, prev], r[rows, k]
    frac = np.where(k > 0, (level - r0) / np.where(r1 > r0, r1 - r0, 1.0), 0.0)
    crossing = t[prev] + frac * (t[k] - t[prev])
    return np.where(reached.any(axis=1), crossing, np.nan)


def step_response(
    time: np.ndarray,
    y: np.ndarray,
    event: StepEvent,
    band: float,
    steady_window: float,
    transient_window: float | None = None,
) -> dict[str, np.ndarray]:
    """Overshoot (%), settling time (s), steady-state error (%) and 10–90 % rise time (s) of the
    responses ``y`` (B, K+1) sampled at ``time`` (K+1,) to ``event``, and with a ``transient_window`` (s) the peak error
    after it (see the module docstring)."""
    window = (time >= event.time) & (time < event.end_time)
    t = time[window]
    r = (y[:, window] - event.start_value) / (event.target - event.start_value)
    transient = t < event.time + (np.inf if transient_window is None else transient_window)
    overshoot = 100.0 * np.maximum(0.0, r[:, transient].max(axis=1) - 1.0)
    ts = t[transient]
    outside = np.abs(r[:, transient] - 1.0) > band
    last_out = ts.size - 1 - np.argmax(outside[:, ::-1], axis=1)
    settled = ~outside[:, -1]
    first_in = np.minimum(last_out + 1, ts.size - 1)
    settling = np.where(outside.any(axis=1), ts[first_in] - event.time, 0.0)
    settling = np.where(settled, settling, np.nan)
    tail = t >= event.end_time - steady_window
    steady = 100.0 * np.abs(r[:, tail].mean(axis=1) - 1.0)
    low, high = (first_crossing(ts, r[:, transient], level) for level in RISE_LEVELS)
    out = {"overshoot_pct": overshoot, "settling_time_s": settling, "steady_state_error_pct": steady,
           "rise_time_s": high - low}  # fmt: skip
    if transient_window is not None:
        late = np.abs(r[:, ~transient] - 1.0).max(axis=1, initial=-np.inf)
        out["peak_error_pct"] = np.where(np.isfinite(late), 100.0 * late, np.nan)  # NaN: the interval ends first
    return out


def tracking_channels(attitude_mode: bool) -> dict[str, int]:
    """Tracked channel → index into the 16-state truth."""
    if attitude_mode:
        return {"roll": 6, "pitch": 7, "yaw": 8, "altitude": 2}
    return {"x": 0, "y": 1, "altitude": 2, "yaw": 8}


def control_metrics(
    time: np.ndarray,
    truth: np.ndarray,
    reference: np.ndarray,
    command: np.ndarray,
    hover_speed: float,
    attitude_mode: bool,
    events: list[StepEvent],
    band: float,
    steady_window: float,
    transient_window: float | None = None,
) -> dict[str, np.ndarray]:
    """Per-run metrics (name → (B,)) of one batch of flights.

    ``truth`` (B, K+1, 16) is the flown truth, ``reference`` (K+1, 16) the reference laid out as
    the truth (position and attitude slots filled), ``command`` (B, K+1, 4) the rotor-speed commands.
    """
    out: dict[str, np.ndarray] = {}
    for name, j in tracking_channels(attitude_mode).items():
        err = reference[None, :, j] - truth[:, :, j]
        if j == 8:
            err = wrap_angle(err)
        out[f"tracking_rmse_{name}"] = np.sqrt(np.mean(err**2, axis=1))
    for event in events:
        response = step_response(time, truth[:, :, 6 + event.axis], event, band, steady_window, transient_window)
        for key, value in response.items():
            out[f"{key}[{event.label}]"] = value
    out["control_effort"] = np.sqrt(np.mean((command - hover_speed) ** 2, axis=(1, 2)))
    dt = np.diff(time)[None, :, None]
    out["command_rate"] = np.sqrt(np.mean((np.diff(command, axis=1) / dt) ** 2, axis=(1, 2)))
    return out


def mean_ci(values: np.ndarray) -> tuple[float, float, float, int]:
    """Mean, 95 % Student-t confidence interval (lo, hi) and count of the finite ``values``."""
    v = values[np.isfinite(values)]
    if v.size == 0:
        return np.nan, np.nan, np.nan, 0
    m = float(v.mean())
    if v.size == 1:
        return m, np.nan, np.nan, 1
    half = float(mean_and_half_width(v, 0.05)[1])
    return m, m - half, m + half, int(v.size)


def summarize_control(table: pd.DataFrame, by: list[str]) -> pd.DataFrame:
    """Mean and 95 % CI of every metric over the runs, per group of ``by`` columns; ``n`` counts the
    runs with a finite value (not crashed; for settling time, also settled)."""
    rows = []
    for key, group in table.groupby(by, sort=False):
        key = key if isinstance(key, tuple) else (key,)
        for metric, frame in group.groupby("metric", sort=False):
            m, lo, hi, n = mean_ci(frame["value"].to_numpy(dtype=float))
            rows.append({**dict(zip(by, key, strict=True)), "metric": metric, "mean": m, "ci_lo": lo, "ci_hi": hi,
                         "n": n, "runs": len(frame)})  # fmt: skip
    return pd.DataFrame(rows)
