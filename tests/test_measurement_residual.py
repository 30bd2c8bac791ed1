"""Every Gaussian filter conditions on the measurement's residual ``r(z, ẑ)``, not on ``z − ẑ``.

A static target due west of the sensor (bearing π) is seen through a bearing whose noise puts
about half the samples on the −π side of the cut. Wrapped, the residual of a sample is its noise;
subtracted, it is off by 2π, and the filter is thrown across the circle. Every estimator kind with
an innovation (the Gaussian filters: ours, the filterpy baselines, the Huber variants) must stay on
the truth with the wrapped residual, and the same problem with plain subtraction must throw it
off (so the scenario does cross the cut for each kind).
"""

from __future__ import annotations

import numpy as np
import pytest

from quadest.estimators.registry import builtin_estimators, make_estimator
from quadest.models.base import FilterModel

SIGMA = 0.02  # bearing noise (rad)
STEPS = 40
RUNS = 3
TRUTH = np.array([-10.0, 0.0])  # bearing exactly π


def _wrap(a: np.ndarray) -> np.ndarray:
    return (a + np.pi) % (2 * np.pi) - np.pi


class _Bearing(FilterModel):
    """A static 2-D position seen from the origin: ``h = atan2(y, x)``, the residual wrapped (or
    not, to show the scenario crosses the cut). ``fused_unscented``: its ``f``/``h`` take sigma
    points, so the SR-UKF on the compiled backend would take its fused steps but for the residual."""

    name, n, m, nu, dt = "bearing", 2, 1, 0, 1.0
    state_names, state_units, measurement_names = ("x", "y"), ("m", "m"), ("bearing",)
    fused_unscented = True

    def __init__(self, wrap: bool, batch_size: int) -> None:
        self.Q, self.R, self.wrap, self.batch_size = 1e-8 * np.eye(2), np.array([[SIGMA**2]]), wrap, batch_size

    def f(self, x, u):
        return x.copy()

    def h(self, x, u):
        return np.arctan2(x[..., 1:2], x[..., 0:1])

    def H_analytic(self, x, u):
        r2 = x[..., 0] ** 2 + x[..., 1] ** 2
        return np.stack([-x[..., 1] / r2, x[..., 0] / r2], axis=-1)[..., None, :]

    def F_analytic(self, x, u):
        return np.broadcast_to(np.eye(2), (*x.shape[:-1], 2, 2)).copy()

    def measurement_residual(self, z, predicted):
        return _wrap(z - predicted) if self.wrap else z - predicted


GAUSSIAN_KINDS = sorted(
    name
    for name, spec in builtin_estimators().items()
    if spec.source.startswith("quadest.") and "innovation" in spec.cls.capabilities
)
CASES = [(kind, {}) for kind in GAUSSIAN_KINDS] + [
    ("srukf", {"augmented": True}),
    ("ckf", {"augmented": True}),
    ("srukf", {"robust": True}),
    # positive weights (W0 = 1/3): the default α = 0.5 gives W0 = −3, whose arithmetic mean of points
    # straddling the cut happens to land near ±π; these do not
    ("ukf", {"alpha": 1.0, "beta": 0.0, "kappa": 1.0}),
    ("srukf", {"alpha": 1.0, "beta": 0.0, "kappa": 1.0}),
]
IDS = [kind + "".join(f"-{key}={value}" for key, value in params.items()) for kind, params in CASES]


def _final_bearing_error(kind: str, params: dict, wrap: bool) -> np.ndarray:
    """Wrapped error of each run's final bearing, NaN for a run the filter flagged."""
    rng = np.random.default_rng(np.random.SeedSequence(20261127))
    z = _wrap(np.pi + SIGMA * rng.standard_normal((RUNS, STEPS, 1)))
    model = _Bearing(wrap, RUNS)
    est = make_estimator(builtin_estimators()[kind].cls, model, params)
    x0 = np.tile([-10.0, 1.0], (RUNS, 1))  # prior bearing ≈ π − 0.1: 5 σ off, inside P0
    P0 = np.tile(np.diag([1.0, 1.0]), (RUNS, 1, 1))
    est.initialize(x0, P0)
    u = np.zeros((RUNS, 0))
    with np.errstate(all="ignore"):
        for k in range(STEPS):
            est.predict(u)
            est.update(z[:, k], u)
    mean = est.mean
    error = np.abs(_wrap(np.arctan2(mean[:, 1], mean[:, 0]) - np.pi))
    return np.where(np.asarray(est.failed) | ~np.isfinite(error), np.nan, error)


def test_the_cases_cover_every_gaussian_kind():
    assert {"ekf", "ukf", "mekf", "hf", "srukf", "ckf", "cdkf", "dd1", "ghkf", "iekf", "iplf"} <= set(GAUSSIAN_KINDS)


@pytest.mark.slow  # its cases together: about 2 s
@pytest.mark.parametrize("kind, params", CASES, ids=IDS)
def test_a_wrapped_bearing_residual_keeps_every_gaussian_filter_on_the_truth(kind, params, monkeypatch):
    """After 40 bearings of σ = 0.02 rad the direction is known to about σ/√40 ≈ 3.2e-3 rad (the
    range is not observable, only the bearing is tested); a filter on the truth lands within
    5 σ/√40 ≈ 0.016 rad. Subtracting instead of wrapping feeds innovations near ±2π: the
    estimate is thrown off by more than that (or the run fails)."""
    monkeypatch.setenv("QUADEST_KERNELS", "numba")  # the SR-UKF's fused path must step aside too
    bound = 5 * SIGMA / np.sqrt(STEPS)
    wrapped = _final_bearing_error(kind, params, wrap=True)
    assert np.all(wrapped < bound), f"{kind}: final bearing errors {wrapped} (bound {bound:.3g})"
    subtracted = _final_bearing_error(kind, params, wrap=False)
    assert np.all(~(subtracted < bound)), f"{kind}: the scenario does not cross the cut ({subtracted})"


@pytest.mark.parametrize("kind, params", CASES, ids=IDS)
def test_sigma_points_on_both_sides_of_the_cut_average_to_the_right_bearing(kind, params, monkeypatch):
    """One update from a prior whose bearing is −π + 0.01 with a spread of ~0.1 rad (P0 = I at
    range 10), so a rule's points straddle the cut, against a measurement at π − 0.01: 0.02 rad
    apart across it. With R = σ² = 4e-4 rad² against the prior's ~1e-2 rad², the posterior bearing
    lands within about 0.02 R/(R + 1e-2) ≈ 8e-4 rad of the measurement (a Gauss–Newton or
    regression step on a curved ``h`` moves it further only at second order); we allow 2e-3.
    Averaging the points' bearings arithmetically puts the predicted bearing near 0, far off."""
    monkeypatch.setenv("QUADEST_KERNELS", "numba")
    model = _Bearing(True, 1)
    est = make_estimator(builtin_estimators()[kind].cls, model, params)
    est.initialize(np.array([[-10.0, -0.1]]), np.eye(2)[None])
    z = np.array([[np.pi - 0.01]])
    est.predict(np.zeros((1, 0)))
    est.update(z, np.zeros((1, 0)))
    error = abs(_wrap(np.arctan2(est.mean[0, 1], est.mean[0, 0]) - z[0, 0]))
    assert not est.failed[0] and error < 2e-3, f"{kind}: posterior bearing {error:.3g} rad from the measurement"


PARTICLE_CASES = [("pf", {}), ("pf", {"kernel": "fast"}), ("ekpf", {}), ("upf", {}), ("ilopf", {})]


def _particle_bearing_error(kind: str, params: dict, wrap: bool) -> np.ndarray:
    """Final bearing error of each run of a particle filter (500 particles, each run its own generator)."""
    rng = np.random.default_rng(np.random.SeedSequence(20261127))
    z = _wrap(np.pi + SIGMA * rng.standard_normal((RUNS, STEPS, 1)))
    model = _Bearing(wrap, RUNS)
    est = make_estimator(builtin_estimators()[kind].cls, model, {"particles": 500, **params})
    est.set_generators([np.random.default_rng(np.random.SeedSequence([7, r])) for r in range(RUNS)])
    est.initialize(np.tile([-10.0, 1.0], (RUNS, 1)), np.tile(np.eye(2), (RUNS, 1, 1)))
    u = np.zeros((RUNS, 0))
    with np.errstate(all="ignore"):
        for k in range(STEPS):
            est.predict(u)
            est.update(z[:, k], u)
    error = np.abs(_wrap(np.arctan2(est.mean[:, 1], est.mean[:, 0]) - np.pi))
    return np.where(np.asarray(est.failed) | ~np.isfinite(error), np.nan, error)


@pytest.mark.slow
@pytest.mark.parametrize(
    "kind, params", PARTICLE_CASES, ids=[k + "".join(f"-{v}" for v in p.values()) for k, p in PARTICLE_CASES]
)
def test_a_wrapped_bearing_residual_keeps_every_particle_filter_on_the_truth(kind, params, monkeypatch):
    """The particle filters weigh each particle by the likelihood of the residual ``r(z, h(x_i))``,
    and the EKF/UKF proposals correct with it (the UKF's points averaged through it). The prior
    cloud's mean is 0.1 rad off the truth. A static state leaves the clouds degenerate, so the
    Gaussian filters' σ/√40 does not hold for them; the threshold is half the prior's offset,
    0.05 rad: a filter that used the bearings moved at least half way (the wrapped runs end within
    0.031 rad), one whose weights vanished stays at its prior cloud (subtracting: 0.076–0.081 rad for
    the bootstrap filter) or is thrown across the circle (the proposals: about 2.9 rad; one UPF run
    of three escapes by luck, so at least one run must be thrown off)."""
    monkeypatch.setenv("QUADEST_KERNELS", "numba")
    bound = 0.05
    wrapped = _particle_bearing_error(kind, params, wrap=True)
    assert np.all(wrapped < bound), f"{kind}: final bearing errors {wrapped} (bound {bound:.3g})"
    subtracted = _particle_bearing_error(kind, params, wrap=False)
    assert np.any(~(subtracted < bound)), f"{kind}: the scenario does not cross the cut ({subtracted})"
