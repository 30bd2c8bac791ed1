"""Tracking figures of the closed loop: the reference and the true response of one run per flight."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from quadest.closed_loop.control_metrics import StepEvent


def plot_tracking(
    time: np.ndarray,
    reference: np.ndarray,
    responses: dict[str, np.ndarray],
    events: list[StepEvent],
    path: Path,
    title: str,
    zoom: float = 2.0,
) -> Path:
    """Roll and pitch (deg) of one run per flight against the reference: the whole run, and
    ``zoom`` seconds after the first step of each axis.

    ``reference`` (K+1, 16) and each response (K+1, 16) are laid out as the truth.
    """
    fig, axes = plt.subplots(2, 2, figsize=(12, 6.5), squeeze=False)
    for row, (axis, name) in enumerate(((0, "roll"), (1, "pitch"))):
        first = next((e for e in events if e.axis == axis), None)
        for col, ax in enumerate(axes[row]):
            window = np.ones_like(time, dtype=bool)
            if col == 1 and first is not None:
                window = (time >= first.time - 0.2 * zoom) & (time <= first.time + zoom)
            ax.plot(time[window], np.rad2deg(reference[window, 6 + axis]), color="k", lw=1.4, ls="--", label="command")
            for label, series in responses.items():
                ax.plot(time[window], np.rad2deg(series[window, 6 + axis]), lw=0.9, label=label)
            ax.set_ylabel(f"{name} [deg]")
            ax.grid(alpha=0.3)
            ax.set_xlabel("time [s]")
    axes[0, 0].legend(fontsize=7, loc="best")
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
