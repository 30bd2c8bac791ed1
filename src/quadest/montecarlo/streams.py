"""Per-run random streams: common random numbers for every estimator.

Randomness comes only from ``np.random.SeedSequence(seed)``: it spawns one child per run, and
each run's child spawns one stream per purpose in :data:`STREAMS` (start point, accelerometer
errors, gyro errors, accelerometer noise, gyro noise, encoder noise, initial estimate, process
and measurement noise of the validation models, the estimators' own randomness, the closed
loop's state sensor, the magnetometer's errors and noise, the GPS, barometer and camera of the
navigation sensors). So every
estimator sees the same draws, run ``i`` is the same whatever the number of runs, and a sweep over
``sensor.error_scale`` scales the same standard-normal draws. Stream ``j`` of run ``i`` is
``SeedSequence(seed, spawn_key=(i, j))``, so appending a stream changes no existing draw.

A sensor from a plugin (docs/sensors.md) is not in :data:`STREAMS`: its streams are *named*,
``SeedSequence(seed, spawn_key=(i, NAMED, *h))`` with ``h`` four 32-bit words of the SHA-256 of
the stream's name (:func:`named_streams`), so they share no draw with the streams above or with
another sensor's, and installing or selecting one changes no existing draw.
"""

from __future__ import annotations

import hashlib

import numpy as np

STREAMS = (
    "start",
    "accel_errors",
    "gyro_errors",
    "accel_noise",
    "gyro_noise",
    "encoder",
    "initial",
    "process",
    "measurement",
    "estimator",
    "state_sensor",
    "mag_errors",
    "mag_noise",
    "gps",
    "barometer",
    "vision",
)  # append only: existing streams keep their draws


def run_seed_sequences(seed: int, runs: int, first_run: int = 0) -> dict[str, list[np.random.SeedSequence]]:
    """One seed sequence per (purpose, run) of runs ``first_run .. first_run + runs − 1``, all from
    ``SeedSequence(seed)``: run ``i``'s is ``SeedSequence(seed, spawn_key=(i,))``, the ``i``-th child
    ``SeedSequence(seed).spawn`` gives, so a batch of runs that starts at ``first_run`` holds the
    same draws as those runs of a job that starts at 0 (``runs=auto``, docs/experiments.md)."""
    children = [np.random.SeedSequence(seed, spawn_key=(i,)) for i in range(first_run, first_run + runs)]
    per_run = [child.spawn(len(STREAMS)) for child in children]
    return {name: [ss[j] for ss in per_run] for j, name in enumerate(STREAMS)}


def run_streams(seed: int, runs: int, first_run: int = 0) -> dict[str, list[np.random.Generator]]:
    """One generator per (purpose, run) of runs ``first_run .. first_run + runs − 1``, all from
    ``SeedSequence(seed)`` (:func:`run_seed_sequences`)."""
    return {
        name: [np.random.default_rng(s) for s in seqs]
        for name, seqs in run_seed_sequences(seed, runs, first_run).items()
    }


NAMED = 2**32 - 1
"""The spawn-key branch of the named streams: never the index of a stream in :data:`STREAMS`."""


def named_seed_sequences(seed: int, runs: int, name: str, first_run: int = 0) -> list[np.random.SeedSequence]:
    """One seed sequence per run (``first_run`` onwards) for the stream called ``name`` (module docstring)."""
    words = [int(w) for w in np.frombuffer(hashlib.sha256(name.encode()).digest()[:16], dtype="<u4")]
    return [np.random.SeedSequence(seed, spawn_key=(i, NAMED, *words)) for i in range(first_run, first_run + runs)]


def named_streams(seed: int, runs: int, name: str, first_run: int = 0) -> list[np.random.Generator]:
    """One generator per run (``first_run`` onwards) for the stream called ``name`` (module docstring)."""
    return [np.random.default_rng(s) for s in named_seed_sequences(seed, runs, name, first_run)]
