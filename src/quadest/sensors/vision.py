"""Camera on the vehicle observing known beacons (seed 004's VisNav, Junkins et al. 1999 line of
work): pixel coordinates, bearing angles or unit line-of-sight vectors of each beacon, at the
camera's own rate.

Frames: earth z up; body x forward, y left, z up (:mod:`quadest.numerics.quaternion`: ``q`` maps
body → earth); camera frame of the pinhole convention (Hartley & Zisserman 2004, §6.1): ``z``
along the optical axis, ``x`` to the image's right, ``y`` down the image. The camera sits at the
centre of mass (no lever arm). For beacon ``b`` (earth) and vehicle position ``p``:

    r_c = C_cb R(q)ᵀ (b − p)                       (line of sight in the camera frame)
    pixel:   (u, v) = (c_x + f x_c/z_c, c_y + f y_c/z_c)   (H&Z eq. 6.1, square pixels, no skew)
    bearing: (α, β) = (atan2(x_c, z_c), atan2(y_c, z_c))    (the two focal-plane angles)
    line_of_sight: r_c / ‖r_c‖                       (seed 004 §1.3.2: the unit line-of-sight vector)

``line_of_sight`` is the VisNav measurement of seed 004 (its §1.3.2 measures the unit vector from
the camera to each beacon in the camera frame; the equation itself is lost from the seed's text, the
form above is the standard one, Crassidis, Alonso & Junkins 2000). Three components per beacon,
each with additive white noise: ``z = r_c/‖r_c‖ + v``; the measured vector is not renormalised,
so the filters' additive model with ``R = σ² I`` describes the draws exactly (the component along
the line of sight carries no information: ``bᵀ ∂b/∂r_c = 0``).

``C_cb`` is the mount: ``forward`` (optical axis along body x) or ``down`` (along body −z, image
up towards body x), then tilted by ``tilt_deg`` about the camera x axis (positive: the optical
axis turns towards the image's down direction, i.e. below the horizon for ``forward``).

Error classes: white noise per sample (``pixel_noise`` in px, ``bearing_noise`` in rad or
``los_noise`` per unit-vector component, ≈ rad, drawn under the sensor's
:class:`~quadest.sensors.noise_laws.NoiseLaw`, independently per component), and two per-run
errors the filters do not know: a mount ``misalignment`` (one-sigma rad per axis, a small rotation
of the camera frame) and a focal-length ``focal_scale`` error (one-sigma fraction; it moves pixels
only). Draw order from the run's ``"vision"`` stream: misalignment (3), focal scale (1), then the
noise (K+1, m), so a change of noise law leaves the per-run errors unchanged.

Availability (every kind): a frame exists every ``round(1/(rate T))`` steps (the rate must divide
the filter rate) and is used only when every beacon is in front of the camera, inside the field of
view that ``focal_length`` and ``image_size`` span and within ``max_range`` in every run of the
batch (the runs differ only by their start point); other frames are dropped (the sample is NaN
and unavailable), since one sensor record has one availability mask for the batch.

:class:`Vision` is the sensor (``model.aiding: [vision, ...]``, settings ``sensor.vision``),
:class:`VisionAiding` the filters' model of it.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from quadest.config.ranges import require_non_negative, require_positive
from quadest.errors import ConfigError
from quadest.numerics import quaternion as quat
from quadest.sensors.base import Sensor, SensorModel, StateLayout, TrueMotion, check_rate, sample_stride
from quadest.sensors.noise_laws import NoiseLaw, check_noise_law, draw_noise
from quadest.sensors.record import SensorRecord

KINDS = ("pixel", "bearing", "line_of_sight")
ROWS = {"pixel": 2, "bearing": 2, "line_of_sight": 3}  # measurement rows per beacon
MOUNTS = ("forward", "down")
_MOUNT_ROWS = {
    "forward": np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]]),
    "down": np.array([[0.0, -1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, -1.0]]),
}


def _default_beacons() -> list[list[float]]:
    """Eight beacons on a 3 m × 1.8 m frame 10 m ahead of the start, the middle pair 0.5 m closer
    (docs/ins.md, "Beacon layout")."""
    return [
        [10.0, -1.5, 0.3],
        [10.0, 0.0, 0.3],
        [10.0, 1.5, 0.3],
        [9.5, -1.5, 1.2],
        [9.5, 1.5, 1.2],
        [10.0, -1.5, 2.1],
        [10.0, 0.0, 2.1],
        [10.0, 1.5, 2.1],
    ]


@dataclass
class VisionSpec:
    """The camera, its beacons and its errors; also the config schema of ``sensor.vision``."""

    rate: float = 20.0
    kind: str = "pixel"
    pixel_noise: float = 0.5
    bearing_noise: float = 2.5e-3
    los_noise: float = 2.5e-3
    focal_length: float = 200.0
    image_size: list[float] = field(default_factory=lambda: [640.0, 480.0])
    mount: str = "forward"
    tilt_deg: float = 0.0
    max_range: float = 30.0
    misalignment: float = 0.0
    focal_scale: float = 0.0
    beacons: list[list[float]] = field(default_factory=_default_beacons)
    noise_law: NoiseLaw = field(default_factory=NoiseLaw)

    @property
    def beacon_array(self) -> np.ndarray:
        return np.asarray(self.beacons, dtype=float).reshape(-1, 3)

    @property
    def noise_std(self) -> float:
        """The white-noise standard deviation in the unit of the measurement (px, rad, or unit
        vector component)."""
        return {"pixel": self.pixel_noise, "bearing": self.bearing_noise, "line_of_sight": self.los_noise}[self.kind]

    @property
    def m(self) -> int:
        return ROWS[self.kind] * self.beacon_array.shape[0]

    def measurement_names(self) -> tuple[str, ...]:
        parts = {"pixel": ("u", "v"), "bearing": ("azimuth", "elevation"), "line_of_sight": ("los_x", "los_y", "los_z")}
        return tuple(f"beacon{i + 1}_{c}" for i in range(self.beacon_array.shape[0]) for c in parts[self.kind])


def mount_rotation(mount: str, tilt_deg: float) -> np.ndarray:
    """``C_cb`` (3, 3): body → camera, the mount's axes then the tilt about the camera x axis."""
    t = np.deg2rad(tilt_deg)
    tilt = np.array([[1.0, 0.0, 0.0], [0.0, np.cos(t), -np.sin(t)], [0.0, np.sin(t), np.cos(t)]])
    return tilt @ _MOUNT_ROWS[mount]


def line_of_sight(q: np.ndarray, p: np.ndarray, beacons: np.ndarray, C_cb: np.ndarray) -> np.ndarray:
    """``r_c = C_cb R(q)ᵀ (b − p)`` (..., N, 3) for attitudes ``q`` (..., 4), positions ``p`` (..., 3)
    and beacons (N, 3); ``C_cb`` (3, 3) or per leading index (..., 3, 3)."""
    r_e = beacons - p[..., None, :]
    r_b = np.einsum("...ji,...nj->...ni", quat.rotation_matrix(q), r_e)
    return np.einsum("...ij,...nj->...ni", C_cb, r_b)


def project(r_c: np.ndarray, kind: str, focal_length, principal_point) -> np.ndarray:
    """Measurements (..., 2N or 3N) of lines of sight (..., N, 3): pixels ``c + f (x, y)/z``,
    bearings ``(atan2(x, z), atan2(y, z))`` or unit vectors ``r_c/‖r_c‖``. ``focal_length`` may
    carry the leading axes (per run)."""
    x, y, z = r_c[..., 0], r_c[..., 1], r_c[..., 2]
    if kind == "line_of_sight":
        out = r_c / np.linalg.norm(r_c, axis=-1, keepdims=True)
    elif kind == "pixel":
        f = np.asarray(focal_length)[..., None] if np.ndim(focal_length) else focal_length
        out = np.stack([principal_point[0] + f * x / z, principal_point[1] + f * y / z], axis=-1)
    else:
        out = np.stack([np.arctan2(x, z), np.arctan2(y, z)], axis=-1)
    return out.reshape(*out.shape[:-2], -1)


def in_view(r_c: np.ndarray, spec: VisionSpec) -> np.ndarray:
    """Whether each line of sight (..., N, 3) is in front of the camera, inside the image and
    within ``max_range`` → (..., N) bool."""
    width, height = spec.image_size
    x, y, z = r_c[..., 0], r_c[..., 1], r_c[..., 2]
    ahead = z > 0.0
    safe_z = np.where(ahead, z, 1.0)
    inside = (np.abs(x / safe_z) <= 0.5 * width / spec.focal_length) & (
        np.abs(y / safe_z) <= 0.5 * height / spec.focal_length
    )
    return ahead & inside & (np.linalg.norm(r_c, axis=-1) <= spec.max_range)


def measure_vision(
    spec: VisionSpec, q_true: np.ndarray, p_true: np.ndarray, sample_period: float, rngs: list[np.random.Generator]
) -> SensorRecord:
    """Camera frames (B, K+1, 2N) of the true attitudes (B, K+1, 4) and positions (B, K+1, 3): the
    run's per-run errors, then white noise; NaN and unavailable between frames and when a beacon
    is out of view in some run (module docstring)."""
    B, K1 = q_true.shape[:2]
    beacons = spec.beacon_array
    C_nominal = mount_rotation(spec.mount, spec.tilt_deg)
    centre = 0.5 * np.asarray(spec.image_size, dtype=float)
    values = np.empty((B, K1, spec.m))
    visible = np.ones(K1, dtype=bool)
    for i, rng in enumerate(rngs):
        tilt_error = spec.misalignment * rng.standard_normal(3)
        focal = spec.focal_length * (1.0 + spec.focal_scale * rng.standard_normal())
        C_true = quat.rotation_matrix(quat.exp(tilt_error)) @ C_nominal
        r_c = line_of_sight(q_true[i], p_true[i], beacons, C_true)
        visible &= in_view(r_c, spec).all(axis=-1)
        values[i] = project(r_c, spec.kind, focal, centre) + draw_noise(
            spec.noise_law, rng, (K1, spec.m), spec.noise_std
        )
    available = (np.arange(K1) % sample_stride(spec.rate, sample_period, f"{Vision.key()}.rate") == 0) & visible
    values[:, ~available] = np.nan
    return SensorRecord(values, available)


def projection_jacobian(r_c: np.ndarray, kind: str, focal_length: float) -> np.ndarray:
    """``∂ project / ∂r_c`` (..., N, 2, 3) at lines of sight (..., N, 3): ``f [[1/z, 0, −x/z²],
    [0, 1/z, −y/z²]]`` for pixels; for bearings ``∂ atan2(x, z) = (z, 0, −x)/(x² + z²)`` and
    ``∂ atan2(y, z) = (0, z, −y)/(y² + z²)``; for unit vectors (..., N, 3, 3)
    ``∂(r/‖r‖)/∂r = (I − b bᵀ)/‖r‖`` with ``b = r/‖r‖``."""
    if kind == "line_of_sight":
        norm = np.linalg.norm(r_c, axis=-1)[..., None, None]
        b = r_c[..., :, None] / norm
        return (np.eye(3) - b * np.swapaxes(b, -1, -2)) / norm
    x, y, z = r_c[..., 0], r_c[..., 1], r_c[..., 2]
    zero = np.zeros_like(x)
    if kind == "pixel":
        rows = [[focal_length / z, zero, -focal_length * x / z**2], [zero, focal_length / z, -focal_length * y / z**2]]
    else:
        sx, sy = x**2 + z**2, y**2 + z**2
        rows = [[z / sx, zero, -x / sx], [zero, z / sy, -y / sy]]
    return np.stack([np.stack(row, axis=-1) for row in rows], axis=-2)


@dataclass
class VisionAiding(SensorModel):
    """Beacon pixels, bearings or unit line-of-sight vectors through the nominal camera (module
    docstring): ``r_c = C_cb R(q)ᵀ (b − p)``, so ``∂r_c/∂δθ = C_cb [r_b]×`` and
    ``∂r_c/∂p = −C_cb R(q)ᵀ``, chained with the kind's ``∂ project/∂r_c``.

    With ``moving_platform`` the beacons ``b`` are in the frame of a platform that translates
    without rotating, and the input carries its known position (the layout's
    ``platform_position``; seed 004 links the platform's navigation data to the vehicle,
    docs/seed004-landing.md): ``b − p`` becomes ``b − (p − p_P)``, the same Jacobians at the
    relative position."""

    spec: VisionSpec
    C_cb: np.ndarray
    R: np.ndarray
    layout: StateLayout
    moving_platform: bool = False

    @property
    def names(self) -> tuple[str, ...]:  # type: ignore[override]
        return self.spec.measurement_names()

    @property
    def _centre(self) -> np.ndarray:
        return 0.5 * np.asarray(self.spec.image_size, dtype=float)

    def _relative_position(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """The vehicle's position relative to the platform, (B, K, 3) or (B, 3)."""
        p = self.quantity("position", x, u)
        if not self.moving_platform:
            return p
        platform = self.quantity("platform_position", x, u)
        return p - (platform[:, None, :] if p.ndim == 3 else platform)

    def h(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        p = self._relative_position(x, u)
        r_c = line_of_sight(self.quantity("attitude", x, u), p, self.spec.beacon_array, self.C_cb)
        return project(r_c, self.spec.kind, self.spec.focal_length, self._centre)

    def jacobian(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        q, p = self.quantity("attitude", x, u), self._relative_position(x, u)
        R_q = quat.rotation_matrix(q)
        r_b = np.einsum("bji,bnj->bni", R_q, self.spec.beacon_array - p[:, None, :])
        r_c = np.einsum("ij,bnj->bni", self.C_cb, r_b)
        D = projection_jacobian(r_c, self.spec.kind, self.spec.focal_length) @ self.C_cb  # (B, N, rows, 3)
        J = self._zeros(x)
        rows = slice(None)
        self.place(J, rows, "attitude", (D @ quat.skew(r_b)).reshape(x.shape[0], -1, 3), x, u)
        self.place(J, rows, "position", -(D @ np.swapaxes(R_q, -1, -2)[:, None]).reshape(x.shape[0], -1, 3), x, u)
        return J


class Vision(Sensor):
    """The camera and its beacons (module docstring); ``R = σ² I`` with the kind's white-noise
    ``σ`` times the model's ``measurement_noise_inflation``. On a scenario with a moving platform
    the beacons are in the platform's frame and the model must offer ``platform_position``."""

    config_name = "vision"
    Settings = VisionSpec
    streams = ("vision",)
    measures = ("position", "attitude")
    moving_platform = False  # set by simulate from the truth

    @classmethod
    def validate(cls, settings: VisionSpec, key: str, sample_period: float) -> None:
        v = settings
        check_rate(f"{key}.rate", v.rate, sample_period)
        if v.kind not in KINDS:
            raise ConfigError(f"{key}.kind", v.kind, f"one of {list(KINDS)}")
        if v.mount not in MOUNTS:
            raise ConfigError(f"{key}.mount", v.mount, f"one of {list(MOUNTS)}")
        for name in ("pixel_noise", "bearing_noise", "los_noise", "focal_length", "max_range"):
            require_positive(f"{key}.{name}", getattr(v, name))
        for name in ("misalignment", "focal_scale"):
            require_non_negative(f"{key}.{name}", getattr(v, name))
        if len(v.image_size) != 2 or min(v.image_size) <= 0:
            raise ConfigError(f"{key}.image_size", list(v.image_size), "two sizes [width, height] > 0 in px")
        beacons = [list(b) for b in v.beacons]
        if len(beacons) < 3 or any(len(b) != 3 for b in beacons):
            raise ConfigError(f"{key}.beacons", beacons, "at least 3 beacons, each [x, y, z] in m (earth frame)")
        check_noise_law(f"{key}.noise_law", v.noise_law)

    def simulate(self, truth: TrueMotion, streams: Mapping[str, list[np.random.Generator]]) -> SensorRecord:
        self.moving_platform = truth.platform is not None
        relative = truth.position if truth.platform is None else truth.position - truth.platform
        return measure_vision(self.settings, truth.attitude, relative, self.context.sample_period, streams["vision"])

    def measurement_model(self, layout: StateLayout) -> VisionAiding:
        spec, moving = self.settings, self.moving_platform
        if moving and "platform_position" not in layout.inputs:
            raise ValueError("a moving beacon platform needs a model whose input carries platform_position")
        R = self.context.noise_inflation * spec.noise_std**2 * np.eye(spec.m)
        return VisionAiding(spec, mount_rotation(spec.mount, spec.tilt_deg), R, layout, moving_platform=moving)
