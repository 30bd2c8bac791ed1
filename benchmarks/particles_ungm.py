"""The ``particles`` library's bootstrap filter on UNGM, timed: the third column of
``bench_particle.py``. Runs in a *separate* environment (``particles`` 0.4 pins numpy < 2, so it
must never be a quadest dependency); imports only numpy and particles, never quadest.

Usage (``bench_particle.py --particles-python PYTHON`` does this for you)::

    python particles_ungm.py MEASUREMENTS.npy PARTICLES

``MEASUREMENTS.npy`` holds (runs, steps) scalar measurements y_1 … y_K (quadest's UNGM data,
written by ``bench_particle.py``). Model, as quadest's ``experiment=ungm_toolbox``:
``x_t = x/2 + 25 x / (1 + x²) + 8 cos(1.2 (t − 1)) + v``, ``y_t = x²/20 + w``, ``v, w ~ N(0, 1)``,
``x_0 ~ N(0.1, 1)``. particles observes its first state, so x_0 gets a flat dummy observation
(N(0, 10¹⁶) likelihood, uniform weights) and y_t observes particles' state t. Bootstrap filter,
stratified resampling at every step (``ESSrmin=1``), no history; one untimed warm-up run first
(particles compiles numba kernels on first use). Prints one JSON line: ns per particle per step over all runs, and
the versions used (Chopin & Papaspiliopoulos 2020, "An Introduction to Sequential Monte Carlo",
the library's book).
"""

from __future__ import annotations

import json
import sys
import time
from importlib.metadata import version

import numpy as np
import particles
from particles import distributions as dists
from particles import state_space_models as ssm


class UNGM(ssm.StateSpaceModel):
    """Univariate nonstationary growth model, Q = R = 1."""

    def PX0(self):
        return dists.Normal(loc=0.1, scale=1.0)

    def PX(self, t, xp):
        return dists.Normal(loc=0.5 * xp + 25.0 * xp / (1.0 + xp**2) + 8.0 * np.cos(1.2 * (t - 1)), scale=1.0)

    def PY(self, t, xp, x):
        return dists.Normal(loc=x**2 / 20.0, scale=1.0 if t > 0 else 1e8)


def main() -> None:
    measurements = np.load(sys.argv[1])
    N = int(sys.argv[2])
    runs, steps = measurements.shape

    def filter_run(data) -> None:
        fk = ssm.Bootstrap(ssm=UNGM(), data=[0.0, *data])  # the dummy observation of x_0 first
        particles.SMC(fk=fk, N=N, resampling="stratified", ESSrmin=1.0, store_history=False, verbose=False).run()

    filter_run(measurements[0, :5])  # first calls compile particles' numba kernels: not timed
    start = time.process_time()
    for run in range(runs):
        filter_run(measurements[run])
    elapsed = time.process_time() - start
    result = {
        "ns_per_particle_step": elapsed / (runs * (steps + 1) * N) * 1e9,  # x_0's step counted too
        "runs": runs,
        "steps": steps,
        "particles": N,
        "particles_version": version("particles"),
        "numpy_version": np.__version__,
    }
    print(json.dumps(result))


if __name__ == "__main__":
    main()
