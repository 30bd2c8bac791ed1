"""Reference trajectories the controller flies: ``hover``, ``attitude_steps``, ``figure8`` and
``platform_approach``, found with any other scenario by :mod:`quadest.quadrotor.scenario_registry`
(docs/scenarios.md).

Every scenario starts at rest on the ground at the origin, with the rotors at hover speed, and
takes off smoothly to its altitude. References are smooth (quintic transitions), so the
backstepping controller receives consistent first and second derivatives.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from quadest.config.ranges import require_non_negative, require_positive


@dataclass
class Reference:
    """What the controller should track at one instant (same for every run of a batch).

    ``position``, ``velocity``, ``acceleration`` (3,) are used in full in position mode; in
    attitude mode only their z components are used (altitude hold) and roll and pitch come from
    ``attitude``. ``attitude``, ``attitude_rate``, ``attitude_accel`` (3,) always give the yaw.
    """

    position: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray
    attitude: np.ndarray
    attitude_rate: np.ndarray
    attitude_accel: np.ndarray
    attitude_mode: bool


def smooth_step(t: float, start: float, duration: float) -> tuple[float, float, float]:
    """Quintic 0 → 1 transition over [start, start + duration]: value, first and second derivative."""
    if duration <= 0.0:
        return (1.0 if t >= start else 0.0), 0.0, 0.0
    s = min(max((t - start) / duration, 0.0), 1.0)
    value = s**3 * (10.0 - 15.0 * s + 6.0 * s**2)
    d1 = 30.0 * s**2 * (1.0 - s) ** 2 / duration
    d2 = 60.0 * s * (1.0 - s) * (1.0 - 2.0 * s) / duration**2
    return value, d1, d2


@dataclass
class Scenario:
    """Base scenario: take off to ``altitude`` in ``takeoff_time`` seconds and hold level.

    ``initial_position_std`` (m) scatters the horizontal start point of each Monte Carlo run, so
    that the runs fly different (nearby) true trajectories.
    """

    name: str = "hover"
    initial_position_std: float = 0.05
    altitude: float = 1.0
    takeoff_time: float = 3.0

    def validate(self, prefix: str = "scenario") -> None:
        """Raise :class:`~quadest.errors.ConfigError` naming the first key out of range, before any
        work (``prefix``: where the node sits); a scenario with keys of its own extends it."""
        require_non_negative(f"{prefix}.initial_position_std", self.initial_position_std)
        require_positive(f"{prefix}.altitude", self.altitude)
        require_non_negative(f"{prefix}.takeoff_time", self.takeoff_time)

    def _takeoff(self, t: float) -> tuple[float, float, float]:
        s, ds, dds = smooth_step(t, 0.0, self.takeoff_time)
        return self.altitude * s, self.altitude * ds, self.altitude * dds

    def reference(self, t: float) -> Reference:
        z, dz, ddz = self._takeoff(t)
        zero = np.zeros(3)
        return Reference(
            np.array([0.0, 0.0, z]), np.array([0.0, 0.0, dz]), np.array([0.0, 0.0, ddz]),
            zero, zero, zero, attitude_mode=False,
        )  # fmt: skip


@dataclass
class Hover(Scenario):
    """Take off to ``altitude`` and hold position (scenario ``hover``)."""

    name: str = "hover"


@dataclass
class AttitudeSteps(Scenario):
    """Roll, pitch and yaw steps with reversals at constant altitude (scenario ``attitude_steps``).

    As in the closed-loop comparison paper (seed 003), the attitude channels are commanded
    directly; horizontal position is not held. ``steps`` lists ``[time_s, axis, angle_deg]`` with
    axis 0 = roll, 1 = pitch, 2 = yaw; each step is a quintic transition of
    ``transition_time`` seconds from the previous value of that axis.
    """

    name: str = "attitude_steps"
    takeoff_time: float = 2.0
    transition_time: float = 0.5
    steps: list[list[float]] = field(
        default_factory=lambda: [
            [3.0, 0, 15.0], [5.0, 0, -15.0], [7.0, 0, 0.0],
            [8.0, 1, 15.0], [10.0, 1, -15.0], [12.0, 1, 0.0],
            [13.0, 2, 20.0], [15.5, 2, -20.0], [18.0, 2, 0.0],
        ]
    )  # fmt: skip

    def validate(self, prefix: str = "scenario") -> None:
        super().validate(prefix)
        require_positive(f"{prefix}.transition_time", self.transition_time)

    def reference(self, t: float) -> Reference:
        ref = super().reference(t)
        angle, rate, accel = np.zeros(3), np.zeros(3), np.zeros(3)
        for start, axis, target_deg in sorted(self.steps, key=lambda step: step[0]):
            if t < start:
                break
            a = int(axis)
            jump = np.deg2rad(target_deg) - angle[a]
            s, ds, dds = smooth_step(t, start, self.transition_time)
            angle[a] += jump * s
            rate[a], accel[a] = jump * ds, jump * dds
        ref.attitude, ref.attitude_rate, ref.attitude_accel = angle, rate, accel
        ref.attitude_mode = True
        return ref


@dataclass
class Figure8(Scenario):
    """An aggressive 3-D figure eight with a yaw sweep (scenario ``figure8``).

    ``x = A sin φ``, ``y = (A/2) sin 2φ``, ``z = h + Az sin φ``, ``ψ = Ψ sin φ``, with the phase
    ``φ(t)`` accelerating smoothly from rest to ``2π / period`` over ``spin_up_time`` seconds
    after take-off.
    """

    name: str = "figure8"
    takeoff_time: float = 2.0
    amplitude: float = 2.0
    vertical_amplitude: float = 0.3
    yaw_amplitude_deg: float = 30.0
    period: float = 6.0
    spin_up_time: float = 3.0

    def validate(self, prefix: str = "scenario") -> None:
        super().validate(prefix)
        require_positive(f"{prefix}.period", self.period)
        require_positive(f"{prefix}.spin_up_time", self.spin_up_time)

    def _phase(self, t: float) -> tuple[float, float, float]:
        w = 2.0 * np.pi / self.period
        tau = t - self.takeoff_time
        if tau <= 0.0:
            return 0.0, 0.0, 0.0
        T = self.spin_up_time
        if tau >= T:
            # ∫ of the quintic ramp over [0, T] is T/2
            return w * (T / 2.0 + tau - T), w, 0.0
        s = tau / T
        integral = T * (s**4 * (2.5 - 3.0 * s + s**2))
        value, d1, _ = smooth_step(tau, 0.0, T)
        return w * integral, w * value, w * d1

    def reference(self, t: float) -> Reference:
        ref = super().reference(t)
        ph, dph, ddph = self._phase(t)
        s, c = np.sin(ph), np.cos(ph)
        s2, c2 = np.sin(2 * ph), np.cos(2 * ph)
        A, Az, Y = self.amplitude, self.vertical_amplitude, np.deg2rad(self.yaw_amplitude_deg)
        shape = np.array([A * s, 0.5 * A * s2, Az * s, Y * s])
        d_shape = np.array([A * c, A * c2, Az * c, Y * c])
        dd_shape = np.array([-A * s, -2.0 * A * s2, -Az * s, -Y * s])
        pos, vel = shape, d_shape * dph
        acc = dd_shape * dph**2 + d_shape * ddph
        ref.position = ref.position + pos[:3]
        ref.velocity = ref.velocity + vel[:3]
        ref.acceleration = ref.acceleration + acc[:3]
        ref.attitude = np.array([0.0, 0.0, pos[3]])
        ref.attitude_rate = np.array([0.0, 0.0, vel[3]])
        ref.attitude_accel = np.array([0.0, 0.0, acc[3]])
        return ref


@dataclass
class PlatformApproach(Scenario):
    """Approach a platform moving straight at constant velocity and end above it (scenario
    ``platform_approach``; seed 004's landing: 60 m from the platform at the start, 2 m above it at
    the end, the platform at 2 m/s).

    The platform's reference point moves as ``p_P(t) = platform_start + t · platform_velocity``. The
    reference blends the take-off point ``A(t) = [0, 0, z_takeoff(t)]`` into ``B(t) = p_P(t) +
    [0, 0, final_height]`` with the quintic ``s(t)`` of :func:`smooth_step` over
    ``[0, approach_time]``: ``r = A + s (B − A)``, its derivatives by the product rule. The vehicle
    starts at rest and, from ``approach_time`` on, holds ``B(t)`` with the platform's velocity.
    """

    name: str = "platform_approach"
    altitude: float = 5.0
    takeoff_time: float = 5.0
    platform_start: list[float] = field(default_factory=lambda: [60.0, 0.0, 1.0])
    platform_velocity: list[float] = field(default_factory=lambda: [2.0, 0.0, 0.0])
    final_height: float = 2.0
    approach_time: float = 30.0

    def validate(self, prefix: str = "scenario") -> None:
        super().validate(prefix)
        require_positive(f"{prefix}.approach_time", self.approach_time)

    def platform_position(self, t: np.ndarray | float) -> np.ndarray:
        """The platform's reference point (..., 3) at times ``t`` (...)."""
        t = np.asarray(t, dtype=float)[..., None]
        return np.asarray(self.platform_start, dtype=float) + t * np.asarray(self.platform_velocity, dtype=float)

    def reference(self, t: float) -> Reference:
        ref = super().reference(t)
        s, ds, dds = smooth_step(t, 0.0, self.approach_time)
        gap = self.platform_position(t) + np.array([0.0, 0.0, self.final_height]) - ref.position
        gap_rate = np.asarray(self.platform_velocity, dtype=float) - ref.velocity
        ref.acceleration = ref.acceleration + dds * gap + 2.0 * ds * gap_rate - s * ref.acceleration
        ref.position = ref.position + s * gap
        ref.velocity = ref.velocity + ds * gap + s * gap_rate
        return ref
