"""The closed loop's config: ``loop`` (what the controller is fed), the state sensor of
``loop: measured``, and the limits beyond which a run counts as crashed."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, fields

import numpy as np

from quadest.config.ranges import require_non_negative, require_positive
from quadest.errors import ConfigError

LOOPS = ("open", "truth", "measured", "estimate")


@dataclass
class StateSensorConf:
    """``closed_loop.state_sensor``: one-sigma white noise per sample on what the controller reads
    with ``loop: measured``; seed 003's levels: 5 °/s on the body rates, 2° on the angles (Euler
    angles here; seed 003's 2° is on its airflow angles α, β)."""

    position: float = 0.0
    velocity: float = 0.0
    angle: float = 0.0349066  # rad, 2 deg
    rate: float = 0.0872665  # rad/s, 5 deg/s

    def std(self) -> np.ndarray:
        """(12,) standard deviations over (position, velocity, Euler angles, body rates)."""
        return np.repeat([self.position, self.velocity, self.angle, self.rate], 3).astype(float)


@dataclass
class ClosedLoopConf:
    """``closed_loop``: the state sensor, the crash limits and the step-response settings.

    A run crashes when its roll or pitch exceeds ``max_tilt`` (rad), when it sinks ``ground_depth``
    (m) below the take-off plane, or when the controller's command is not finite. Settling time is
    measured to the ``settling_band`` (fraction of the step); the steady-state error is the mean
    over the last ``steady_window`` seconds before the next step on that axis. ``transient_window``
    (s) bounds the overshoot's peak to the transient after the step and adds the peak error after
    it; ``None`` takes the peak over the whole interval to the next step (and no peak error).
    """

    state_sensor: StateSensorConf = field(default_factory=StateSensorConf)
    max_tilt: float = 1.2
    ground_depth: float = 0.05
    settling_band: float = 0.02
    steady_window: float = 1.0
    transient_window: float | None = None


def validate_loop(loop: str, model_name: str, closed_loop: ClosedLoopConf, controlled: Sequence[str]) -> None:
    """One-line :class:`ConfigError` for a bad ``loop`` (for ``model=<model_name>``; ``controlled``:
    the models with a closed loop, :func:`quadest.closed_loop.loops.controlled_models`) or
    ``closed_loop`` setting, before any work."""
    if loop not in LOOPS:
        raise ConfigError("loop", loop, f"one of {list(LOOPS)}")
    if loop == "open":
        return
    if model_name not in controlled:
        raise ConfigError(
            "loop", loop, f"'open' only for model={model_name} (no controller flies on its filter state); "
            f"closed loops need model in {list(controlled)}",
        )  # fmt: skip
    c = closed_loop
    for f in fields(c.state_sensor):
        require_non_negative(f"closed_loop.state_sensor.{f.name}", getattr(c.state_sensor, f.name))
    require_positive("closed_loop.max_tilt", c.max_tilt, "must be > 0 rad")
    require_non_negative("closed_loop.ground_depth", c.ground_depth)
    if not 0.0 < c.settling_band < 1.0:
        raise ConfigError("closed_loop.settling_band", c.settling_band, "must lie in (0, 1) (fraction of the step)")
    require_positive("closed_loop.steady_window", c.steady_window, "must be > 0 seconds")
    if c.transient_window is not None:
        require_positive("closed_loop.transient_window", c.transient_window, "must be > 0 seconds, or null")
