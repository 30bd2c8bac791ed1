"""``model=attitude`` and the error-state filters: Jacobians on the manifold, observability at rest
and in a manoeuvre, consistency on the figure eight, and the sigma-point filters against the MEKF.

The synthetic cases integrate the truth with the filter's own transition (rates held over each
step, as the model assumes), so every difference from the truth is the filter's, not the
model's."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from scipy.stats import chi2

from helpers import compose_config
from quadest.app.settings import data_settings
from quadest.errors import ConfigError
from quadest.estimators.base import PerRunAdapter
from quadest.estimators.cubature import CKF, SRCKF
from quadest.estimators.error_state_ekf import ErrorStateEKF
from quadest.estimators.filterpy_ekf import BatchedFilterpyEKF
from quadest.estimators.filterpy_ukf import FilterpyUKF
from quadest.estimators.registry import build_estimator
from quadest.estimators.smoothing import rts_backward
from quadest.estimators.srukf import SRUKF
from quadest.metrics.consistency import chi2_band
from quadest.models.attitude import AttitudeFilterModel
from quadest.models.base import FilterModel
from quadest.numerics import quaternion as quat
from quadest.runner import run_estimator
from quadest.sensors.magnetometer import measure_magnetometer
from quadest.sensors.mimu import TriadSpec, draw_triad_errors
from quadest.simulation.registry import build_data

G_EARTH = np.array([0.0, 0.0, -9.81])
M_EARTH = np.array([20.0, 0.0, -45.0])
T = 0.01
SIGMA_GYRO, SIGMA_ACC, SIGMA_MAG = 1e-3, 0.04, 0.2  # per sample: rad/s, m/s², µT
BIAS_WALK = 1e-5  # gyro-bias random walk per step, rad/s


def _model(B: int, Q_scale: float = 1.0, errors: bool = False) -> AttitudeFilterModel:
    Q = Q_scale * np.diag([(SIGMA_GYRO * T) ** 2] * 3 + [BIAS_WALK**2] * 3 + [1e-8] * 3)
    triads = {}
    if errors:
        spec = TriadSpec(scale_factor=0.02, asymmetry=0.005, cross_coupling=0.01, bias=0.5)
        names = ("gyro_errors", "accel_errors", "mag_errors")
        triads = {
            k: draw_triad_errors(spec, [np.random.default_rng(10 * j + i) for i in range(B)])
            for j, k in enumerate(names)
        }
    R_acc, R_mag = SIGMA_ACC**2 * np.eye(3), SIGMA_MAG**2 * np.eye(3)
    return AttitudeFilterModel(T, G_EARTH, M_EARTH, Q, R_acc, R_mag, batch_size=B, **triads)


def _synthetic(model: AttitudeFilterModel, steps: int, rate_amplitude: float, seed: int):
    """Truth (B, K+1, 10), inputs (B, K+1, 6), accelerometer (B, K+1, 3) and magnetometer every
    second step, for a vehicle rotating about a fixed point with body rates
    ``A (sin 0.7t, cos 0.5t, 0.6 sin 0.3t)`` (at rest for A = 0), biases drawn per run."""
    rng = np.random.default_rng(seed)
    B = model.batch_size
    t = np.arange(steps + 1) * T
    omega = rate_amplitude * np.stack([np.sin(0.7 * t), np.cos(0.5 * t), 0.6 * np.sin(0.3 * t)], axis=-1)
    x = np.empty((B, steps + 1, 10))
    x[:, 0, :4] = quat.from_euler(np.array([0.2, -0.1, 0.5]) + 0.1 * rng.standard_normal((B, 3)))
    x[:, 0, 4:7] = 0.01 * rng.standard_normal((B, 3))
    x[:, :, 7:10] = 0.2 * rng.standard_normal((B, 1, 3))
    steps_bias = BIAS_WALK * rng.standard_normal((B, steps + 1, 3))
    steps_bias[:, 0] = 0.0
    x[:, :, 4:7] = x[:, :1, 4:7] + np.cumsum(steps_bias, axis=1)
    gyro = omega[None] + x[..., 4:7] + SIGMA_GYRO * rng.standard_normal((B, steps + 1, 3))
    u = np.concatenate([gyro, np.zeros((B, steps + 1, 3))], axis=-1)
    noiseless = np.concatenate([omega[None] + x[..., 4:7], u[..., 3:]], axis=-1)
    for k in range(steps):
        x[:, k + 1, :4] = model.f(x[:, k : k + 1], noiseless[:, k])[:, 0, :4]
    acc = np.stack([model.h(x[:, k : k + 1], u[:, k])[:, 0] for k in range(steps + 1)], axis=1)
    mag = np.stack([model.h_mag(x[:, k : k + 1], u[:, k])[:, 0] for k in range(steps + 1)], axis=1)
    acc = acc + SIGMA_ACC * rng.standard_normal(acc.shape)
    mag = mag + SIGMA_MAG * rng.standard_normal(mag.shape)
    return x, u, acc, mag


def _filter(est, x_true, u, acc, mag, x0, P0, mag_every: int = 2, steps: list | None = None):
    """Means (K, B, 10) and covariances (K, B, 9, 9) after the updates of each step; the
    magnetometer every ``mag_every`` steps (0: never). With a list ``steps``, the filter records
    its smoother steps there (the K − 1 transitions between the returned estimates)."""
    est.smoothing = steps is not None
    est.initialize(x0.copy(), P0.copy())
    means, covs = [], []
    for k in range(1, u.shape[1]):
        est.predict(u[:, k - 1])
        if steps is not None and k > 1:
            steps.append(est.smoother_step)
        est.update(acc[:, k], u[:, k])
        if mag_every and k % mag_every == 0:
            est.update(mag[:, k], u[:, k], sensor="mag")
        means.append(est.mean.copy())
        covs.append(est.covariance.copy())
    return np.array(means), np.array(covs)


def _prior(B: int, model: AttitudeFilterModel, x_true0: np.ndarray, stds, seed: int):
    P0 = np.diag(np.repeat(np.square(stds), 3))
    w = np.random.default_rng(seed).standard_normal((B, 9)) @ np.linalg.cholesky(P0).T
    return model.boxplus(x_true0, w), np.broadcast_to(P0, (B, 9, 9)).copy()


# --- Jacobians on the manifold ---


def test_analytic_error_state_jacobians_match_finite_differences_on_the_manifold():
    """F_err, H_err (accelerometer, magnetometer) and the reset Jacobian against central
    differences along the error state (the base class's defaults). Central differences with
    h = 1e-6 err by O(h²)·|third derivative| ≈ 1e-12 plus round-off eps·|y|/h ≈ 1e-8 for the
    magnetometer's |y| ≈ 50 µT, so 1e-7 relative to the largest entry separates them from any
    wrong sign or block (O(1) errors)."""
    B = 4
    model = _model(B, errors=True)
    rng = np.random.default_rng(1)
    x = np.concatenate([quat.normalize(rng.standard_normal((B, 4))), 0.05 * rng.standard_normal((B, 6))], axis=-1)
    u = np.concatenate([2.0 * rng.standard_normal((B, 3)), rng.standard_normal((B, 3))], axis=-1)
    dx = 0.2 * rng.standard_normal((B, 9))
    pairs = [
        (model.F_err(x, u), model.manifold_jacobian_fd(model.f, x, u, state_valued=True)),
        (model.H_err(x, u), model.manifold_jacobian_fd(model.h, x, u, state_valued=False)),
        (model.H_err(x, u, "mag"), model.manifold_jacobian_fd(model.h_mag, x, u, state_valued=False)),
        (model.reset_jacobian(x, dx), FilterModel.reset_jacobian(model, x, dx)),
    ]
    for analytic, fd in pairs:
        assert np.abs(analytic - fd).max() <= 1e-7 * np.abs(fd).max()


# --- observability: at rest and in a manoeuvre ---


@pytest.fixture(scope="module")
def rest_and_manoeuvre():
    """8 runs: 30 s at rest with accelerometer and magnetometer, 5 s at rest with the accelerometer
    alone, and 30 s rotating with both."""
    B = 8
    stds = (0.05, 0.01, 0.2)
    out = {}
    for name, steps, amplitude, mag_every in (
        ("rest", 3000, 0.0, 2),
        ("rest_gravity_only", 500, 0.0, 0),
        ("manoeuvre", 3000, 1.0, 2),
    ):
        model = _model(B)
        x, u, acc, mag = _synthetic(model, steps, amplitude, seed=3)
        x0, P0 = _prior(B, model, x[:, 0], stds, seed=4)
        means, covs = _filter(ErrorStateEKF(model), x, u, acc, mag, x0, P0, mag_every)
        out[name] = (model, x, means, covs, P0)
    return out


@pytest.mark.slow
def test_static_vehicle_converges_to_attitude_and_gyro_bias(rest_and_manoeuvre):
    """At rest the attitude drift fixes the gyro bias: σ below 1e-3 rad/s (prior 0.01) and the
    error within 4σ (a 4σ excursion of one of 8 runs × 3 components has probability < 2e-3). The
    magnetometer fixes the attitude except the rotation about the field vector, which only the
    accelerometer can see, and there it trades against the unknown accelerometer bias (a rotation
    by α about m moves gravity in the body by g·sin∠(g, m)·α). So: two principal σ of the attitude
    below 1e-3 rad, the third along the field (|cos| > 0.99) and below its prior ambiguity
    0.2/(g sin∠(g, m)) = 0.05 rad, attitude errors within 4σ."""
    model, x, means, covs, _ = rest_and_manoeuvre["rest"]
    err = model.boxminus(means[-1], x[:, -1])
    sigma = np.sqrt(np.diagonal(covs[-1], axis1=-2, axis2=-1))
    assert np.all(np.abs(err[:, :6]) <= 4.0 * sigma[:, :6])
    assert np.all(sigma[:, 3:6] < 1e-3)
    variances, axes = np.linalg.eigh(covs[-1][:, :3, :3])
    assert np.all(np.sqrt(variances[:, :2]) < 1e-3)
    field = quat.rotate(quat.conjugate(x[:, -1, :4]), np.broadcast_to(M_EARTH, (x.shape[0], 3)))
    field /= np.linalg.norm(field, axis=-1, keepdims=True)
    assert np.all(np.abs(np.einsum("bi,bi->b", axes[:, :, 2], field)) > 0.99)
    sin_gm = np.linalg.norm(np.cross(G_EARTH, M_EARTH)) / (np.linalg.norm(G_EARTH) * np.linalg.norm(M_EARTH))
    assert np.all(np.sqrt(variances[:, 2]) < 0.2 / (9.81 * sin_gm))


@pytest.mark.slow
def test_horizontal_accelerometer_bias_is_unobservable_at_rest_and_observable_in_a_manoeuvre(rest_and_manoeuvre):
    """With gravity as the only reference, a horizontal accelerometer bias and a tilt give the same
    reading at rest (b_a,xy ≈ g δθ): the bias variance in the plane orthogonal to gravity must stay
    near its prior. Conditioning on the sum of two independent unknowns with priors 0.2² (bias) and
    (g·0.05)² (tilt) leaves 0.2²·0.49²/(0.2² + 0.49²) = 86 % of the prior; after 5 s at rest it
    must stay above 70 % (the EKF's linearisation at a moving estimate slowly creates spurious
    information over tens of seconds, docs/attitude.md). The bias along gravity is seen directly:
    below 1 %. Rotating the body separates the bias (fixed in the body) from the tilt (fixed in
    the earth frame): after 30 s below 1 % of the prior, error within 4σ, attitude σ below 5e-3."""
    model, x, _, covs, P0 = rest_and_manoeuvre["rest_gravity_only"]
    prior = P0[0, 6, 6]
    tilt_prior = (9.81 * 0.05) ** 2
    assert 0.8 < tilt_prior / (prior + tilt_prior) < 0.9
    assert np.all(_horizontal_bias_variance(covs[-1], x[:, -1]) > 0.7 * prior)
    assert np.all(_bias_variance_along_gravity(covs[-1], x[:, -1]) < 0.01 * prior)

    model, x, means, covs, _ = rest_and_manoeuvre["manoeuvre"]
    var = np.diagonal(covs[-1], axis1=-2, axis2=-1)
    err = model.boxminus(means[-1], x[:, -1])
    assert np.all(var[:, 6:9] < 0.01 * prior)
    assert np.all(np.abs(err) <= 4.0 * np.sqrt(var))
    assert np.all(np.sqrt(var[:, 0:3]) < 5e-3)


def _gravity_in_body(x_true: np.ndarray) -> np.ndarray:
    down = quat.rotate(quat.conjugate(x_true[:, :4]), np.broadcast_to(G_EARTH, (x_true.shape[0], 3)))
    return down / np.linalg.norm(down, axis=-1, keepdims=True)


def _bias_variance_along_gravity(P: np.ndarray, x_true: np.ndarray) -> np.ndarray:
    g = _gravity_in_body(x_true)
    return np.einsum("bi,bij,bj->b", g, P[:, 6:9, 6:9], g)


def _horizontal_bias_variance(P: np.ndarray, x_true: np.ndarray) -> np.ndarray:
    """The smaller variance of the accelerometer bias in the body plane orthogonal to gravity (the
    body is tilted, so that plane is not exactly b_x, b_y): the middle eigenvalue of the bias
    covariance projected on it (the smallest, zero, is along gravity)."""
    g = _gravity_in_body(x_true)
    projector = np.eye(3) - g[:, :, None] * g[:, None, :]
    return np.linalg.eigvalsh(projector @ P[:, 6:9, 6:9] @ projector)[:, 1]


# --- consistency on the figure eight ---


@pytest.mark.slow
def test_error_state_nees_lies_in_its_chi2_band_on_the_figure_eight():
    """20 runs of 10 s of the figure eight on the shared quadrotor (consumer MIMU, magnetometer at
    50 Hz). NEES on the 9-dimensional error state: 20 × the run-average is χ²(180) when the
    filter is consistent, so each step's run-average lies in [χ²(180, 0.025), χ²(180, 0.975)]/20
    = [7.24, 10.95] with probability 0.95. Steps are correlated, so the fraction inside has a wide
    spread: at least 85 % of the steps, and the time-and-run average within the same band."""
    cfg = compose_config(["model=attitude", "runs=20", "duration=10", "scenario=figure8"])
    data = build_data(data_settings(cfg))
    lo, hi = chi2_band(9, np.full(1, 20))
    assert np.allclose([lo[0], hi[0]], chi2.ppf([0.025, 0.975], 180) / 20)
    result = run_estimator("mekf", build_estimator("mekf", {"kind": "mekf"}, data.model), data, 50.0)
    assert not result.diverged.any()
    nees_t = result.nees_mean_t[1:]
    assert np.mean((nees_t >= lo[0]) & (nees_t <= hi[0])) >= 0.85
    assert lo[0] <= np.nanmean(result.mean_nees) <= hi[0]


# --- sigma-point error-state filters against the MEKF ---


@pytest.mark.parametrize("cls", [SRUKF, CKF, SRCKF])
def test_sigma_point_error_state_filters_equal_the_mekf_on_a_nearly_linear_case(cls):
    """Small prior (σθ = 1e-3 rad, σb_g = 1e-4 rad/s, σb_a = 1e-3 m/s²), 1 s of rotation. The
    filters differ only by terms of second order in the error spread: a sigma-point moment differs
    from the linearised one by O(σθ²) relative to the first-order term, and the MEKF's reset
    Jacobian J_r(δθ) ≈ I − [δθ/2]× (which the sigma-point update does not apply) changes P by
    O(|δθ|) relative, |δθ| ≲ 3σθ. So attitude and biases agree to 1e-2 σ (means) and covariances
    to 5e-3 relative (5 × σθ with σθ = 1e-3, room for the accumulation over 100 steps)."""
    B = 3
    model = _model(B)
    x, u, acc, mag = _synthetic(model, 100, 1.0, seed=7)
    x0, P0 = _prior(B, model, x[:, 0], (1e-3, 1e-4, 1e-3), seed=8)
    ref_m, ref_P = _filter(ErrorStateEKF(model), x, u, acc, mag, x0, P0)
    params = {"alpha": 1.0} if cls is SRUKF else {}
    m, P = _filter(cls(model, **params), x, u, acc, mag, x0, P0)
    sigma = np.sqrt(np.diagonal(ref_P, axis1=-2, axis2=-1))
    assert np.abs(model.boxminus(m, ref_m) / sigma).max() < 1e-2
    assert np.abs(P - ref_P).max() <= 5e-3 * np.abs(ref_P).max()


# --- the reset ---


@pytest.mark.parametrize("reset", [True, False])
def test_mekf_update_is_joseph_then_reset(reset):
    """One update by hand: ``K = P Hᵀ S⁻¹``, ``δ = K ν``, Joseph covariance, and with
    ``reset_jacobian`` the reset ``G P Gᵀ``, ``G = blockdiag(J_r(δθ), I)`` (Solà eq. 287), about
    the new mean ``x ⊞ δ``. A large prior makes ``δθ`` (and so ``G − I``) large enough to see."""
    B = 2
    model = _model(B)
    x, u, acc, _ = _synthetic(model, 1, 0.5, seed=9)
    x0, P0 = _prior(B, model, x[:, 0], (0.3, 0.01, 0.2), seed=10)
    est = ErrorStateEKF(model, reset_jacobian=reset)
    est.initialize(x0, P0)
    est.update(acc[:, 1], u[:, 1])
    H = model.H_err(x0, u[:, 1])
    S = H @ P0 @ np.swapaxes(H, -1, -2) + model.R
    K = P0 @ np.swapaxes(H, -1, -2) @ np.linalg.inv(S)
    d = (K @ (acc[:, 1] - model.h(x0[:, None], u[:, 1])[:, 0])[..., None])[..., 0]
    A = np.eye(9) - K @ H
    P = A @ P0 @ np.swapaxes(A, -1, -2) + K @ model.R @ np.swapaxes(K, -1, -2)
    if reset:
        G = np.broadcast_to(np.eye(9), (B, 9, 9)).copy()
        G[:, :3, :3] = quat.right_jacobian(d[:, :3])
        P = G @ P @ np.swapaxes(G, -1, -2)
    assert np.abs(np.linalg.norm(d[:, :3], axis=-1)).min() > 0.05  # the reset is not negligible
    assert np.allclose(est.mean, model.boxplus(x0, d), atol=1e-12)
    assert np.allclose(est.covariance, P, rtol=1e-10, atol=1e-14)


# --- the magnetometer ---


def test_magnetometer_samples_the_body_field_at_its_rate():
    """Without errors or noise the samples are the earth field in the body frame, checked against
    scipy's rotation (scalar last), at every second step for 50 Hz on a 100 Hz filter, NaN between;
    a rate that does not divide the filter rate is refused naming the key."""
    rng = np.random.default_rng(5)
    q = quat.normalize(rng.standard_normal((2, 7, 4)))
    spec = TriadSpec(white_noise=0.0)
    errors = draw_triad_errors(spec, [np.random.default_rng(i) for i in range(2)])
    record = measure_magnetometer(spec, errors, q, M_EARTH, T, 50.0, [np.random.default_rng(i) for i in range(2)])
    assert record.available.tolist() == [True, False] * 3 + [True]
    assert np.isnan(record.values[:, ~record.available]).all()
    body = Rotation.from_quat(q[:, record.available][..., [1, 2, 3, 0]].reshape(-1, 4)).inv().apply(M_EARTH)
    assert np.allclose(record.values[:, record.available].reshape(-1, 3), body, atol=1e-12)
    with pytest.raises(ConfigError, match=r"model\.magnetometer\.rate"):
        measure_magnetometer(spec, errors, q, M_EARTH, T, 30.0, [np.random.default_rng(i) for i in range(2)])


@pytest.mark.parametrize("model", ["attitude", "ins"])
@pytest.mark.parametrize(
    ("override", "key"),
    [
        ("model.magnetometer.rate=30", "model.magnetometer.rate"),
        ("model.magnetometer.white_noise=0", "model.magnetometer.white_noise"),
        ("model.magnetometer.earth_field=[0,0,0]", "model.magnetometer.earth_field"),
        ("model.magnetometer.bias=-1", "model.magnetometer.bias"),
    ],
)
@pytest.mark.slow
def test_both_models_refuse_a_bad_magnetometer_naming_the_key(model, override, key):
    """One magnetometer (:class:`quadest.sensors.magnetometer.Magnetometer`) for ``model=attitude``
    and ``model=ins``: the same settings are refused by both before any work, with one line."""
    from quadest.app.validate import validate

    with pytest.raises(ConfigError) as info:
        validate(compose_config([f"model={model}", "estimator=[mekf]", override]))
    assert info.value.key == key and "\n" not in str(info.value)


# --- the filterpy baselines in error coordinates ---


def _smoothed(est, *args):
    """The fixed-interval smoothed means and covariances of :func:`_filter`'s run."""
    steps: list = []
    means, covs = _filter(est, *args, steps=steps)
    return rts_backward(list(means), covs[-1], steps, est.smoothing_form())


@pytest.mark.parametrize("run", [_filter, _smoothed], ids=["filter", "smoother"])
def test_filterpy_ekf_on_the_manifold_is_the_mekf_without_reset_jacobian(run):
    """filterpy's EKF carrying the error state about a reference (``estimators/local_coordinates``)
    is the multiplicative EKF with Markley's reset (``reset_jacobian: false``): the same Jacobians,
    the same Joseph update. Only the linear algebra differs (filterpy inverts S, the MEKF solves
    with it), so they agree to round-off: relative 1e-16 amplified by cond(S) ≲ 1e4 and by 100
    steps of accumulation stays below 1e-9 of σ. Their RTS smoothers too: the same smoother steps,
    the correction injected with ⊞, the backward pass solving with the same predicted covariances."""
    B = 3
    model = _model(B, errors=True)
    x, u, acc, mag = _synthetic(model, 100, 1.0, seed=11)
    x0, P0 = _prior(B, model, x[:, 0], (0.05, 0.01, 0.1), seed=12)
    ref_m, ref_P = run(ErrorStateEKF(model, reset_jacobian=False), x, u, acc, mag, x0, P0)
    m, P = run(BatchedFilterpyEKF(model), x, u, acc, mag, x0, P0)
    sigma = np.sqrt(np.diagonal(ref_P, axis1=-2, axis2=-1))
    assert np.abs(model.boxminus(m, ref_m) / sigma).max() < 1e-9
    assert np.abs(P - ref_P).max() <= 1e-9 * np.abs(ref_P).max()
    if run is _smoothed:
        filtered_m, _ = _filter(ErrorStateEKF(model, reset_jacobian=False), x, u, acc, mag, x0, P0)
        assert np.abs(model.boxminus(filtered_m[:-1], ref_m[:-1]) / sigma[:-1]).max() > 1e-3  # it did smooth


def test_filterpy_ukf_on_the_manifold_equals_the_mekf_on_a_nearly_linear_case():
    """filterpy's UKF in error coordinates (USQUE) against the MEKF: the same second-order
    argument and tolerances as the family's sigma-point filters above."""
    B = 3
    model = _model(B)
    x, u, acc, mag = _synthetic(model, 100, 1.0, seed=7)
    x0, P0 = _prior(B, model, x[:, 0], (1e-3, 1e-4, 1e-3), seed=8)
    ref_m, ref_P = _filter(ErrorStateEKF(model), x, u, acc, mag, x0, P0)
    m, P = _filter(PerRunAdapter(model, FilterpyUKF, alpha=1.0), x, u, acc, mag, x0, P0)
    sigma = np.sqrt(np.diagonal(ref_P, axis1=-2, axis2=-1))
    assert np.abs(model.boxminus(m, ref_m) / sigma).max() < 1e-2
    assert np.abs(P - ref_P).max() <= 5e-3 * np.abs(ref_P).max()


def test_filterpy_ukf_smoother_on_the_manifold_equals_the_mekf_smoother_on_a_nearly_linear_case():
    """The unscented smoother of filterpy's UKF in error coordinates (USQUE) against the MEKF's:
    the second-order argument and tolerances of the filters' test."""
    B = 3
    model = _model(B)
    x, u, acc, mag = _synthetic(model, 100, 1.0, seed=7)
    x0, P0 = _prior(B, model, x[:, 0], (1e-3, 1e-4, 1e-3), seed=8)
    ref_m, ref_P = _smoothed(ErrorStateEKF(model, reset_jacobian=False), x, u, acc, mag, x0, P0)
    m, P = _smoothed(PerRunAdapter(model, FilterpyUKF, alpha=1.0), x, u, acc, mag, x0, P0)
    sigma = np.sqrt(np.diagonal(ref_P, axis1=-2, axis2=-1))
    assert np.abs(model.boxminus(m, ref_m) / sigma).max() < 1e-2
    assert np.abs(P - ref_P).max() <= 5e-3 * np.abs(ref_P).max()


def test_filterpy_ukf_per_point_and_vectorised_agree_on_the_manifold():
    """The per-point use of filterpy's UKF and the vectorised one are the same filter."""
    B = 2
    model = _model(B)
    x, u, acc, mag = _synthetic(model, 20, 1.0, seed=3)
    x0, P0 = _prior(B, model, x[:, 0], (0.05, 0.01, 0.1), seed=4)
    m1, P1 = _filter(PerRunAdapter(model, FilterpyUKF), x, u, acc, mag, x0, P0)
    m2, P2 = _filter(PerRunAdapter(model, FilterpyUKF, vectorize_points=False), x, u, acc, mag, x0, P0)
    assert np.allclose(m1, m2, rtol=0, atol=1e-12) and np.allclose(P1, P2, rtol=1e-10, atol=1e-16)
