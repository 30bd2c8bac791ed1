"""A scenario from outside quadest: take off, hold, then climb smoothly by ``height`` metres."""

from dataclasses import dataclass

from quadest.config.ranges import require_non_negative, require_positive
from quadest.quadrotor.scenarios import Reference, Scenario, smooth_step


@dataclass
class Climb(Scenario):
    """Take off to ``altitude``, then from ``climb_start`` on climb ``height`` metres more in
    ``climb_time`` seconds along the quintic of :func:`smooth_step`."""

    name: str = "climb"
    height: float = 2.0
    climb_start: float = 4.0
    climb_time: float = 3.0

    def reference(self, t: float) -> Reference:
        ref = super().reference(t)
        s, ds, dds = smooth_step(t, self.climb_start, self.climb_time)
        ref.position[2] += self.height * s
        ref.velocity[2] += self.height * ds
        ref.acceleration[2] += self.height * dds
        return ref

    def validate(self, prefix: str = "scenario") -> None:
        super().validate(prefix)
        require_positive(f"{prefix}.height", self.height)
        require_non_negative(f"{prefix}.climb_start", self.climb_start)
        require_positive(f"{prefix}.climb_time", self.climb_time)
