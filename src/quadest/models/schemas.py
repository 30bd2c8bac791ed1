"""Structured-config schemas of the ``model`` group: one dataclass per ``model=`` option.

Each option's schema sits beside its filter model and data builder in the model registry
(:mod:`quadest.simulation.registry`); :func:`quadest.app.schema.register_schemas` stores them
under ``/schema/model/<name>``, where the YAML options pull them from.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from quadest.sensors.magnetometer import MagnetometerConf


@dataclass
class ProcessNoiseConf:
    """One-sigma process noise per sample period, per state group (see docs/filter-models.md)."""

    velocity: float = 0.01
    angle: float = 1.0e-4
    angle_rate: float = 0.01


@dataclass
class InitialStdConf:
    """One-sigma of the initial estimate error, per state group; P0 is built from these."""

    velocity: float = 0.2
    angle: float = 0.02
    angle_rate: float = 0.1
    correlation: float = 0.0


@dataclass
class ControllerConf:
    """Backstepping gains (α1, α2) per channel group and the tilt limit (rad)."""

    position: list[float] = field(default_factory=lambda: [1.5, 2.0])
    altitude: list[float] = field(default_factory=lambda: [2.0, 3.0])
    attitude: list[float] = field(default_factory=lambda: [10.0, 10.0])
    yaw: list[float] = field(default_factory=lambda: [5.0, 5.0])
    max_tilt: float = 0.6


@dataclass
class QuadrotorFlightConf:
    """The shared quadrotor: the OS4 truth, the filter formulation, and the quadrotor filters'
    noise; the base of every model option flown on it."""

    name: str = "quadrotor"
    formulation: str = "thesis"
    calibrated: bool = True
    mass: float = 0.65
    arm: float = 0.23
    inertia: list[float] = field(default_factory=lambda: [7.5e-3, 7.5e-3, 1.3e-2])
    rotor_inertia: float = 6.0e-5
    thrust_factor: float = 3.13e-5
    drag_factor: float = 7.5e-7
    gravity: float = 9.81
    translational_drag: list[float] = field(default_factory=lambda: [0.25, 0.25, 0.25])
    rotational_drag: list[float] = field(default_factory=lambda: [1.0e-3, 1.0e-3, 1.0e-3])
    motor_time_constant: float = 0.05
    rotor_speed_min: float = 24.0
    rotor_speed_max: float = 340.0
    truth_substeps: int = 10
    process_noise: ProcessNoiseConf = field(default_factory=ProcessNoiseConf)
    measurement_noise_inflation: float = 1.0
    initial_std: InitialStdConf = field(default_factory=InitialStdConf)
    controller: ControllerConf = field(default_factory=ControllerConf)


@dataclass
class QuadrotorModelConf(QuadrotorFlightConf):
    """``model=quadrotor``: the shared quadrotor and its further sensors, ``aiding`` (in update
    order; any registered sensor whose measured quantities the filter state holds: the velocity,
    docs/sensors.md)."""

    aiding: list[str] = field(default_factory=list)


@dataclass
class LinearModelConf:
    """``model=linear``: 2-D constant velocity, positions measured (validation model)."""

    name: str = "linear"
    acceleration_psd: float = 0.5
    position_noise_std: float = 0.5
    measurement_correlation: float = 0.3
    initial_state: list[float] = field(default_factory=lambda: [0.0, 0.0, 1.0, -0.5])
    initial_std: list[float] = field(default_factory=lambda: [1.0, 1.0, 0.5, 0.5])
    initial_correlation: float = 0.2


@dataclass
class UNGMModelConf:
    """``model=ungm``: univariate nonstationary growth model (validation model).

    ``Q``, ``R``: noise variances; the truth starts from N(x0_mean, x0_var); every filter starts
    from mean ``m0`` and variance ``P0``.
    """

    name: str = "ungm"
    Q: float = 1.0
    R: float = 1.0
    x0_mean: float = 0.1
    x0_var: float = 0.0
    m0: float = 0.1
    P0: float = 1.0


@dataclass
class UPFBenchmarkModelConf:
    """``model=upf_benchmark``: the scalar benchmark of van der Merwe et al. (2000)
    (:mod:`quadest.models.upf_benchmark`). ``Q`` is the process-noise variance of the Gaussian
    filters; the truth's noise is Gamma(``gamma_shape``, rate ``gamma_rate``); ``x0`` is known."""

    name: str = "upf_benchmark"
    Q: float = 0.75
    R: float = 1.0e-5
    gamma_shape: float = 3.0
    gamma_rate: float = 2.0
    switch_time: float = 30.0
    x0: float = 1.0
    P0: float = 0.75


@dataclass
class Seed001RatesModelConf(QuadrotorFlightConf):
    """``model=seed001_rates``: seed 001's angular-rate filter on the shared quadrotor
    (:mod:`quadest.models.seed001_rates`); ``Q``, ``R``, ``P0`` are variances per axis, (rad/s)²;
    ``truth`` is how the true rates are made (:data:`~quadest.models.seed001_rates.TRUTHS`)."""

    name: str = "seed001_rates"
    truth: str = "own_model"
    Q: float = 0.1
    R: float = 0.1
    P0: float = 0.1


@dataclass
class Seed003AttitudeModelConf(QuadrotorFlightConf):
    """``model=seed003_attitude``: seed 003's 5-state filter (φ, θ, p, q, r) on the shared quadrotor
    (:mod:`quadest.models.seed003_attitude`); ``Q`` and ``R`` are the five diagonal variances."""

    name: str = "seed003_attitude"
    Q: list[float] = field(default_factory=lambda: [2.0e-10, 2.0e-10, 4.0e-8, 4.0e-8, 4.0e-8])
    R: list[float] = field(default_factory=lambda: [0.0012, 0.0012, 0.0076, 0.0076, 0.0076])


@dataclass
class AttitudeProcessNoiseConf:
    """``model=attitude`` process noise: ``attitude`` (rad per step) on top of the gyro's white
    noise, for model error of the attitude propagation; ``inflation`` multiplies the whole Q."""

    attitude: float = 0.0
    inflation: float = 1.0


@dataclass
class AttitudeInitialStdConf:
    """One-sigma of the initial error: attitude (rad per axis), gyro bias (rad/s), accelerometer
    bias (m/s²); defaults: the consumer MIMU's turn-on biases."""

    attitude: float = 0.05
    gyro_bias: float = 8.73e-3
    accel_bias: float = 0.196


@dataclass
class AttitudeModelConf(QuadrotorFlightConf):
    """``model=attitude`` (:mod:`quadest.models.attitude`): quaternion, gyro and accelerometer
    biases on the shared quadrotor, accelerometer and magnetometer updates (docs/attitude.md).
    The inherited quadrotor keys fly the truth; its ``process_noise``/``initial_std`` groups belong
    to the quadrotor filters and are not read here (``attitude_process_noise``/``attitude_initial_std`` are).
    ``recording``: null flies the truth; a file or an EuRoC-layout folder (docs/euroc.md) replays its
    IMU against its reference instead."""

    name: str = "attitude"
    known_acceleration: bool = True
    acceleration_std: float = 1.0
    magnetometer: MagnetometerConf = field(default_factory=MagnetometerConf)
    attitude_process_noise: AttitudeProcessNoiseConf = field(default_factory=AttitudeProcessNoiseConf)
    attitude_initial_std: AttitudeInitialStdConf = field(default_factory=AttitudeInitialStdConf)
    recording: str | None = None


@dataclass
class InsProcessNoiseConf:
    """``model=ins`` process noise: one-sigma terms per step (rad, m, m/s) on top of the IMU's white
    noise, for what the mechanisation neglects (0: with Δθ/Δv inputs at T = 0.01 s the neglected
    terms are below the IMU noise, docs/ins.md); ``inflation`` multiplies the whole Q."""

    attitude: float = 0.0
    position: float = 0.0
    velocity: float = 0.0
    inflation: float = 1.0


@dataclass
class InsInitialStdConf:
    """One-sigma of the initial error: attitude (rad per axis), position (m), velocity (m/s), gyro
    bias (rad/s), accelerometer bias (m/s²); bias defaults: the consumer MIMU's turn-on biases."""

    attitude: float = 0.05
    position: float = 0.3
    velocity: float = 0.1
    gyro_bias: float = 8.73e-3
    accel_bias: float = 0.196


@dataclass
class InsModelConf(QuadrotorFlightConf):
    """``model=ins`` (:mod:`quadest.models.ins`, docs/ins.md): strapdown INS with quaternion,
    position, velocity and both biases, aided by ``aiding`` (in update order; GPS, barometer and
    camera from ``sensor.gps``/``sensor.barometer``/``sensor.vision``, the magnetometer from
    ``model.magnetometer``). The inherited quadrotor keys fly the truth; ``process_noise`` and
    ``initial_std`` belong to the quadrotor filters (``ins_process_noise``/``ins_initial_std`` are
    read here). ``recording``: null flies the truth; a file or an EuRoC-layout folder
    (:mod:`quadest.simulation.euroc`) replays its IMU against its reference instead."""

    name: str = "ins"
    attitude_chart: str = "rotation_vector"
    aiding: list[str] = field(default_factory=lambda: ["gps", "barometer", "vision", "magnetometer"])
    magnetometer: MagnetometerConf = field(default_factory=MagnetometerConf)
    ins_process_noise: InsProcessNoiseConf = field(default_factory=InsProcessNoiseConf)
    ins_initial_std: InsInitialStdConf = field(default_factory=InsInitialStdConf)
    recording: str | None = None


@dataclass
class BookPendulumModelConf:
    """``model=book_pendulum``: the noisy pendulum of Särkkä & Svensson (2023), Example 5.1
    (:mod:`quadest.models.book_pendulum`). ``g``, ``q_c`` (spectral density of the process noise),
    ``R`` (measurement-noise variance); every filter starts from ``m0`` with covariance
    ``diag(P0)``; ``x0`` is the true initial state. ``recording``: null simulates the truth and
    the measurements from the model; a file (JSON, CSV or NPZ, docs/models.md) replays its
    recorded runs instead (a relative path is looked up in quadest's shipped ``data/`` first)."""

    name: str = "book_pendulum"
    g: float = 9.81
    q_c: float = 0.01
    R: float = 0.1
    m0: list[float] = field(default_factory=lambda: [0.0, 0.0])
    P0: list[float] = field(default_factory=lambda: [1.0, 1.0])
    x0: list[float] = field(default_factory=lambda: [1.5, 0.0])
    recording: str | None = None
