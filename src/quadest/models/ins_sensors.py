"""The aiding sensors of ``model=ins`` as the filters see them: each one's ``h`` on the 16-state
INS and its analytic error-state Jacobian (B, m, 15) for the error-state filters (docs/ins.md).

State layout (shared with :mod:`quadest.models.ins`): ``[q (0:4), p (4:7), v (7:10),
b_g (10:13), b_a (13:16)]``; error state ``[δθ (0:3), δp (3:6), δv (6:9), δb_g, δb_a]`` with
``q_true = q ⊗ exp(δθ)``, so ``∂(R(q ⊞ δθ)ᵀ r)/∂δθ = [R(q)ᵀ r]×`` (Solà 2017 eq. 186 with the
right perturbation).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, replace

import numpy as np

from quadest.numerics import quaternion as quat
from quadest.sensors.gps import GPSSpec, gps_prediction
from quadest.sensors.magnetometer import field_in_body
from quadest.sensors.mimu import TriadErrors
from quadest.sensors.vision import VisionSpec, line_of_sight, project, projection_jacobian

ATT, POS, VEL = slice(0, 4), slice(4, 7), slice(7, 10)
PLATFORM = slice(6, 9)  # the input's platform position (after the IMU's 6), with a moving platform
N_ERR = 15


class AidingSensor(ABC):
    """One aiding sensor: ``h(x, u)`` (B, K, m), ``jacobian(x, u)`` (B, m, 15), ``R`` and ``names``."""

    R: np.ndarray
    names: tuple[str, ...]

    @abstractmethod
    def h(self, x: np.ndarray, u: np.ndarray) -> np.ndarray: ...

    @abstractmethod
    def jacobian(self, x: np.ndarray, u: np.ndarray) -> np.ndarray: ...

    def select(self, runs: slice | np.ndarray) -> AidingSensor:
        """The sensor bound to a subset of runs (a slice or index array; the same sensor unless it
        carries per-run values)."""
        return self

    def _zeros(self, x: np.ndarray) -> np.ndarray:
        return np.zeros((x.shape[0], self.R.shape[0], N_ERR))


@dataclass
class GpsAiding(AidingSensor):
    """Position (and velocity) with the receiver's latency ``delay`` compensated to first order:
    ``h = [p − delay·v, v]`` (:func:`~quadest.sensors.gps.gps_prediction`)."""

    spec: GPSSpec
    delay: float
    R: np.ndarray

    @property
    def names(self) -> tuple[str, ...]:  # type: ignore[override]
        return self.spec.measurement_names()

    def h(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        return gps_prediction(x[..., POS], x[..., VEL], self.delay, self.spec.measure_velocity)

    def jacobian(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        J = self._zeros(x)
        J[:, 0:3, 3:6] = np.eye(3)
        J[:, 0:3, 6:9] = -self.delay * np.eye(3)
        if self.spec.measure_velocity:
            J[:, 3:6, 6:9] = np.eye(3)
        return J


@dataclass
class BarometerAiding(AidingSensor):
    """Altitude ``h = z``."""

    R: np.ndarray
    names: tuple[str, ...] = ("baro_z",)

    def h(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        return x[..., 6:7].copy()

    def jacobian(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        J = self._zeros(x)
        J[:, 0, 5] = 1.0
        return J


@dataclass
class VisionAiding(AidingSensor):
    """Beacon pixels, bearings or unit line-of-sight vectors through the nominal camera
    (:mod:`quadest.sensors.vision`): ``r_c = C_cb R(q)ᵀ (b − p)``, so ``∂r_c/∂δθ = C_cb [r_b]×``
    and ``∂r_c/∂δp = −C_cb R(q)ᵀ``, chained with the kind's ``∂ project/∂r_c``.

    With ``moving_platform`` the beacons ``b`` are in the frame of a platform that translates
    without rotating, and the input carries its known position ``p_P = u[6:9]`` (seed 004 links the
    platform's navigation data to the vehicle; docs/seed004-landing.md): ``b − p`` becomes
    ``b − (p − p_P)``, the same Jacobians at the relative position."""

    spec: VisionSpec
    C_cb: np.ndarray
    R: np.ndarray
    moving_platform: bool = False

    @property
    def names(self) -> tuple[str, ...]:  # type: ignore[override]
        return self.spec.measurement_names()

    @property
    def _centre(self) -> np.ndarray:
        return 0.5 * np.asarray(self.spec.image_size, dtype=float)

    def _relative_position(self, p: np.ndarray, u: np.ndarray) -> np.ndarray:
        """The vehicle's position relative to the platform, ``p`` (B, K, 3) or (B, 3)."""
        if not self.moving_platform:
            return p
        platform = u[:, PLATFORM]
        return p - (platform[:, None, :] if p.ndim == 3 else platform)

    def h(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        p = self._relative_position(x[..., POS], u)
        r_c = line_of_sight(x[..., ATT], p, self.spec.beacon_array, self.C_cb)
        return project(r_c, self.spec.kind, self.spec.focal_length, self._centre)

    def jacobian(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        q, p = x[:, ATT], self._relative_position(x[:, POS], u)
        R_q = quat.rotation_matrix(q)
        r_b = np.einsum("bji,bnj->bni", R_q, self.spec.beacon_array - p[:, None, :])
        r_c = np.einsum("ij,bnj->bni", self.C_cb, r_b)
        D = projection_jacobian(r_c, self.spec.kind, self.spec.focal_length) @ self.C_cb  # (B, N, rows, 3)
        J = self._zeros(x)
        J[:, :, 0:3] = (D @ quat.skew(r_b)).reshape(x.shape[0], -1, 3)
        J[:, :, 3:6] = -(D @ np.swapaxes(R_q, -1, -2)[:, None]).reshape(x.shape[0], -1, 3)
        return J


@dataclass
class MagnetometerAiding(AidingSensor):
    """The earth field through the magnetometer's known soft/hard-iron errors (per run):
    ``h = M(R(q)ᵀ m_e)``, ``∂h/∂δθ = M' [m_b]×`` (as :mod:`quadest.models.attitude`)."""

    mag_earth: np.ndarray
    errors: TriadErrors
    R: np.ndarray
    names: tuple[str, ...] = ("mag_x", "mag_y", "mag_z")

    def select(self, runs: slice | np.ndarray) -> MagnetometerAiding:
        return replace(self, errors=self.errors[runs])

    def h(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        return self.errors.apply(field_in_body(x[..., ATT], self.mag_earth))

    def jacobian(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        m_b = field_in_body(x[:, ATT], self.mag_earth)
        J = self._zeros(x)
        J[:, :, 0:3] = self.errors.jacobian(m_b) @ quat.skew(m_b)
        return J
