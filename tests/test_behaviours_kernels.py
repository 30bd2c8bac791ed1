"""Compiled kernels against their numpy references where the shipped numbers hide a bug.

- The quadrotor model's compiled ``f`` and ``h`` (:mod:`quadest.models.quadrotor_kernels`) equal
  ``f_numpy``/``h_numpy`` with every physical parameter of ``conf/model/quadrotor.yaml`` (the fields
  of :class:`~quadest.quadrotor.params.QuadrotorParams` found in the config) drawn at random, each
  axis of a vector on its own: the shipped ``Ix = Iy`` and equal drag on every axis make an
  exchanged axis or a flipped ``(Ix − Iy)`` invisible. Tolerance as in ``tests/test_kernels.py``:
  the same expressions, libm against numpy's sine and cosine and the order of three-term sums,
  32 eps (|x| + |out|) per run; an exchanged axis differs by the parameters' spread.
- The compiled diagonal Gaussian log-density is numpy's bit for bit for every dimension from 1 to
  40 and for a few past numpy's 128-term pairwise blocks: numpy sums fewer than 8 terms left to
  right, then with 8 accumulators and a remainder, and the kernel must form the same sum.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from helpers import compose_config, compose_settings
from quadest.models.base import _gaussian_logpdf
from quadest.numerics.draws import particle_kernels as active_kernels
from quadest.quadrotor.params import QuadrotorParams
from quadest.sensors.mimu import TriadErrors
from quadest.simulation.quadrotor_data import build_quadrotor_data

EPS = np.finfo(float).eps
SHIPPED = compose_config(["model=quadrotor"]).model
PHYSICAL = [f.name for f in dataclasses.fields(QuadrotorParams) if f.name in SHIPPED and f.name != "rotor_speed_min"
            and f.name != "rotor_speed_max"]  # fmt: skip


def randomised_overrides(seed: int) -> tuple[list[str], dict]:
    """Every physical parameter times a factor in [0.5, 2] (each vector entry its own factor)."""
    rng = np.random.default_rng(seed)
    values = {}
    for name in PHYSICAL:
        shipped = np.asarray(SHIPPED[name], dtype=float)
        values[name] = shipped * np.exp(rng.uniform(np.log(0.5), np.log(2.0), shipped.shape))
    overrides = [f"model.{k}=[{','.join(repr(float(x)) for x in v)}]" if v.ndim else f"model.{k}={float(v)!r}"
                 for k, v in values.items()]  # fmt: skip
    return overrides, values


@pytest.mark.parametrize("formulation", ["thesis", "augmented"])
@pytest.mark.parametrize("seed", range(3))
def test_quadrotor_kernels_equal_numpy_with_randomised_parameters(formulation, seed, monkeypatch):
    monkeypatch.setenv("QUADEST_KERNELS", "numba")
    overrides, values = randomised_overrides(seed)
    data = build_quadrotor_data(compose_settings([f"model.formulation={formulation}", "runs=3", "duration=0.1",
                                                  "progress=false", *overrides]))  # fmt: skip
    model = data.model
    for name, value in values.items():  # the draws reached the model
        np.testing.assert_array_equal(np.asarray(getattr(model.params, name), dtype=float), value)
    assert len(set(model.params.inertia)) == 3
    rng = np.random.default_rng(100 + seed)
    x = data.x0[:, None, :] + 0.5 * rng.standard_normal((data.x0.shape[0], 13, model.n))
    u = model.filter_input(data.inputs[:, 0], data.companion_truth[:, 0])
    u[:, :4] *= rng.uniform(0.8, 1.2, (u.shape[0], 4))  # unequal rotor speeds: every torque acts
    if model.thesis:
        u[:, 4:7] += 0.3 * rng.standard_normal((u.shape[0], 3))
    uncalibrated = model.select(slice(None))
    uncalibrated.accel_errors = uncalibrated.gyro_errors = TriadErrors.nominal(model.batch_size)
    for m in (model, uncalibrated):
        for fn in ("f", "h"):
            out, ref = getattr(m, fn)(x, u), getattr(m, f"{fn}_numpy")(x, u)
            tol = 32 * EPS * (np.abs(x).max(axis=(1, 2)) + np.abs(ref).max(axis=(1, 2)))
            error = np.abs(out - ref).max(axis=(1, 2))
            assert (error <= tol).all(), (fn, error, tol)


@pytest.mark.parametrize("r", [*range(1, 41), 127, 128, 129, 200, 257])
def test_compiled_diagonal_log_density_is_numpys_bit_for_bit_in_every_dimension(r, monkeypatch):
    rng = np.random.default_rng(r)
    scale = rng.uniform(0.05, 6.0, r)
    C = np.diag(scale**2)
    e = 10.0 ** rng.uniform(-3, 3, (3, 40, r)) * rng.standard_normal((3, 40, r))  # magnitudes over six decades
    monkeypatch.setenv("QUADEST_KERNELS", "numpy")
    assert active_kernels() is None
    reference = _gaussian_logpdf(e, C, scale)
    monkeypatch.setenv("QUADEST_KERNELS", "numba")
    assert active_kernels() is not None
    np.testing.assert_array_equal(_gaussian_logpdf(e, C, scale), reference)
