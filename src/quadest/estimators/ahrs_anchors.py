"""Anchors a user would pick instead: Madgwick, Mahony and the quaternion EKF of the ``ahrs``
package (Garcia 2019-, ``pip install quadest[anchors]``), as single-run plugins of any model with
the attitude model's layout (``model=attitude``: state ``[q, b_g, b_a]``, input ``[ω_m, …]``,
accelerometer as the primary measurement, magnetometer as sensor ``"mag"``).

- Madgwick: S. Madgwick, A. Harrison, R. Vaidyanathan, "Estimation of IMU and MARG orientation
  using a gradient descent algorithm", ICORR 2011 (``ahrs.filters.Madgwick``, gain β; no
  gyro-bias estimate);
- Mahony: R. Mahony, T. Hamel, J.-M. Pflimlin, "Nonlinear complementary filters on the special
  orthogonal group", IEEE TAC 53(5), 2008 (``ahrs.filters.Mahony``, gains k_P, k_I; its integral
  term is the gyro-bias estimate, reported as ``b_g``; its earth frame has north on +y, converted);
- EKF: ``ahrs.filters.EKF``, an EKF on the four quaternion components with the *normalised*
  accelerometer and magnetometer as measurements (no bias states).

Conventions. The three take a body→earth quaternion, scalar first, and expect the accelerometer
to point along the earth's +z axis at rest. The model's accelerometer reads
``R(q)ᵀ (a_e − g_e)``, so the sample passed on is ``−sign(g_e,z) z``: as measured for a z-up earth
frame (the simulation), negated for NED (a PX4 log, where gravity is +z). Their magnetic
reference lies in the x–z plane (x: magnetic north), which the model's ``mag_earth`` is.

Timing. The runner calls ``predict(u_{k−1})`` then ``update(z_k)`` and, when a magnetometer sample
exists at step k, ``update(m_k, sensor="mag")``. The ahrs filters integrate the gyro and correct in
one call, with the accelerometer alone (``updateIMU``) or with the magnetometer (``updateMARG``);
so ``update`` makes the IMU step from the previous estimate, and a magnetometer sample at the same
step makes that step again as a MARG step from the same starting point (and the same internal
state: Mahony's bias integral, the EKF's covariance).

Covariance: none. Madgwick and Mahony have no covariance, and the ahrs EKF's 4×4 covariance of
quaternion components is not one of the 9-dimensional error state. They declare the
``"no_covariance"`` capability: the runner reports their NEES as unavailable, not as divergence,
and their ``covariance`` is NaN.
"""

from __future__ import annotations

from abc import abstractmethod
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from quadest.estimators.base import SingleRunEstimator
from quadest.estimators.params import ranged
from quadest.models.base import FilterModel
from quadest.numerics import quaternion as quat

#: ahrs' Mahony puts magnetic north on its earth frame's +y axis (``v_m = Rᵀ [0, |h_xy|, h_z]``),
#: the model and the other two on +x. With the same z axis the Mahony frame's axes are
#: ``(−y, x, z)`` of the model's, so ``q_model = q_z(−90°) ⊗ q_mahony``.
_NORTH_Y_TO_X = quat.from_euler(np.array([0.0, 0.0, -np.pi / 2]))


def _import_filters():
    try:
        from ahrs import filters
    except ImportError as exc:
        raise ImportError(f"the ahrs anchors need the 'ahrs' package: pip install 'quadest[anchors]' ({exc})") from None
    return filters


def _positive(estimator: str, **values: float) -> tuple[float, ...]:
    """An anchor's tuning constants as floats; a ValueError naming ``estimator`` unless all are > 0."""
    if not all(v > 0 for v in values.values()):
        got = ", ".join(f"{name}={v}" for name, v in values.items())
        raise ValueError(f"{estimator}: {', '.join(values)} must be > 0, got {got}")
    return tuple(float(v) for v in values.values())


class _AhrsAnchor(SingleRunEstimator):
    """One ahrs filter behind the single-run interface (see the module docstring)."""

    capabilities: ClassVar[frozenset[str]] = frozenset({"no_covariance"})

    def __init__(self, model: FilterModel) -> None:
        super().__init__(model)
        g_e = np.asarray(getattr(model, "gravity_earth", np.full(3, np.nan)), dtype=float)
        if not ("mag" in model.sensors and model.n == 10 and g_e[2] != 0 and np.allclose(g_e[:2], 0.0)):
            raise ValueError(
                f"{type(self).__name__} needs an attitude model (state [q, b_g, b_a], sensor 'mag', gravity along "
                f"the earth z axis), got model '{model.name}'"
            )
        self._up = -np.sign(g_e[2])  # the accelerometer sign that makes it point along earth +z at rest
        self._filters = _import_filters()

    def initialize(self, x0: np.ndarray, P0: np.ndarray) -> None:
        self.x = np.array(x0, dtype=float)
        self.x[4:] = 0.0
        self.filter = self._make()
        self._gyro = np.zeros(3)

    def predict(self, u: np.ndarray) -> None:
        self._gyro = np.array(u[:3], dtype=float)

    def update(self, z: np.ndarray, u: np.ndarray, sensor: str | None = None) -> None:
        if sensor is None:
            self._start = (self.x.copy(), self._internal_state())
            self._acc = self._up * np.asarray(z, dtype=float)
            self.x[:4] = self._step(self.x[:4], self._acc, None)
        elif sensor == "mag":
            x, internal = self._start
            self.x = x.copy()
            self._restore(internal)
            self.x[:4] = self._step(x[:4], self._acc, np.asarray(z, dtype=float))
        else:
            raise KeyError(f"{type(self).__name__} knows the sensor 'mag' only, got {sensor!r}")

    @property
    def mean(self) -> np.ndarray:
        return self.x

    @property
    def covariance(self) -> np.ndarray:
        return np.full((self.model.n_err, self.model.n_err), np.nan)

    @abstractmethod
    def _make(self):
        """The ahrs filter object."""

    @abstractmethod
    def _step(self, q: np.ndarray, acc: np.ndarray, mag: np.ndarray | None) -> np.ndarray:
        """One ahrs step from ``q`` with the stored gyro: IMU (``mag`` None) or MARG."""

    def _internal_state(self) -> np.ndarray | None:
        """A copy of what the ahrs object changes in a step besides ``q`` (none for Madgwick)."""
        return None

    def _restore(self, internal: np.ndarray | None) -> None:
        """Put back what :meth:`_internal_state` saved."""


@dataclass
class MadgwickParams:
    """``estimator=madgwick``: the gradient-descent gains with and without the magnetometer
    (the ahrs defaults, Madgwick 2011 §7)."""

    kind: str = "madgwick"
    gain_imu: float = ranged(0.033, "β with the accelerometer alone", gt=0.0)
    gain_marg: float = ranged(0.041, "β with accelerometer and magnetometer", gt=0.0)


class AhrsMadgwick(_AhrsAnchor):
    """``ahrs.filters.Madgwick`` (Madgwick et al. 2011)."""

    config_name: ClassVar[str] = "madgwick"
    Params: ClassVar[type] = MadgwickParams

    def __init__(self, model: FilterModel, gain_imu: float = 0.033, gain_marg: float = 0.041) -> None:
        super().__init__(model)
        self.gains = _positive("madgwick", gain_imu=gain_imu, gain_marg=gain_marg)

    def _make(self):
        return self._filters.Madgwick(Dt=self.model.dt, gain_imu=self.gains[0], gain_marg=self.gains[1])

    def _step(self, q, acc, mag):
        f = self.filter
        if mag is None:
            f.gain = f.gain_imu
            return f.updateIMU(q, self._gyro, acc)
        f.gain = f.gain_marg
        return f.updateMARG(q, self._gyro, acc, mag)


@dataclass
class MahonyParams:
    """``estimator=mahony``: proportional and integral gains (rad/s; the ahrs defaults)."""

    kind: str = "mahony"
    k_P: float = ranged(1.0, "proportional gain", gt=0.0)
    k_I: float = ranged(0.3, "integral gain (gyro-bias estimate)", gt=0.0)


class AhrsMahony(_AhrsAnchor):
    """``ahrs.filters.Mahony`` (Mahony et al. 2008); its bias integral is reported as ``b_g``."""

    config_name: ClassVar[str] = "mahony"
    Params: ClassVar[type] = MahonyParams

    def __init__(self, model: FilterModel, k_P: float = 1.0, k_I: float = 0.3) -> None:
        super().__init__(model)
        self.gains = _positive("mahony", k_P=k_P, k_I=k_I)  # ahrs refuses k_I = 0

    def _make(self):
        return self._filters.Mahony(Dt=self.model.dt, k_P=self.gains[0], k_I=self.gains[1])

    def _step(self, q, acc, mag):
        f = self.filter
        q_north_y = quat.multiply(quat.conjugate(_NORTH_Y_TO_X), q)
        if mag is None:
            q_north_y = f.updateIMU(q_north_y, self._gyro, acc)
        else:
            q_north_y = f.updateMARG(q_north_y, self._gyro, acc, mag)
        self.x[4:7] = f.b
        return quat.multiply(_NORTH_Y_TO_X, q_north_y)

    def _internal_state(self) -> np.ndarray:
        return self.filter.b.copy()

    def _restore(self, internal: np.ndarray) -> None:
        self.filter.b = internal.copy()


@dataclass
class AhrsEKFParams:
    """``estimator=ahrs_ekf``: the spectral noise variances of ``ahrs.filters.EKF``: gyro in
    (rad/s)², accelerometer and magnetometer as *unit* vectors (the ahrs defaults)."""

    kind: str = "ahrs_ekf"
    var_gyr: float = ranged(0.3**2, "gyro noise variance, (rad/s)^2", gt=0.0)
    var_acc: float = ranged(0.5**2, "noise variance of the unit accelerometer vector", gt=0.0)
    var_mag: float = ranged(0.8**2, "noise variance of the unit magnetometer vector", gt=0.0)


class AhrsEKF(_AhrsAnchor):
    """``ahrs.filters.EKF``: quaternion-component EKF without bias states."""

    config_name: ClassVar[str] = "ahrs_ekf"
    Params: ClassVar[type] = AhrsEKFParams

    def __init__(self, model: FilterModel, var_gyr: float = 0.3**2, var_acc: float = 0.5**2, var_mag: float = 0.8**2):
        super().__init__(model)
        self.noises = _positive("ahrs_ekf", var_gyr=var_gyr, var_acc=var_acc, var_mag=var_mag)

    def _make(self):
        var_gyr, var_acc, var_mag = self.noises
        return self._filters.EKF(
            Dt=self.model.dt,
            frame="NED",
            magnetic_ref=np.array(self.model.mag_earth, dtype=float),
            var_gyr=var_gyr,
            var_acc=var_acc,
            var_mag=var_mag,
        )

    def _step(self, q, acc, mag):
        self.filter.mag = mag  # ahrs' EKF sizes its measurement by this attribute, not by the argument
        return self.filter.update(q, self._gyro, acc, mag=mag, dt=self.model.dt)

    def _internal_state(self) -> np.ndarray:
        return self.filter.P.copy()

    def _restore(self, internal: np.ndarray) -> None:
        self.filter.P = internal.copy()
