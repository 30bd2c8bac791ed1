"""The discretised Wiener velocity (continuous white-noise acceleration) model of one axis and of a
plane (Bar-Shalom, Li & Kirubarajan 2001, §6.2.2; Särkkä & Svensson 2023, Ex. 4.3): position and
velocity driven by white acceleration of spectral density ``q``, sampled every ``dt``.
"""

from __future__ import annotations

import numpy as np


def wiener_velocity_block(q: float, dt: float) -> np.ndarray:
    """``Q`` of one axis, state (position, velocity): ``q [[dt³/3, dt²/2], [dt²/2, dt]]``."""
    return float(q) * np.array([[dt**3 / 3.0, dt**2 / 2.0], [dt**2 / 2.0, dt]])


def constant_velocity_plane(q: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """``(A, Q)`` of the state ``(x, y, vx, vy)``: ``A = [[I, dt I], [0, I]]`` and each axis's
    :func:`wiener_velocity_block` on its (position, velocity) pair."""
    A = np.eye(4)
    A[0, 2] = A[1, 3] = dt
    block = wiener_velocity_block(q, dt)
    Q = np.zeros((4, 4))
    Q[np.ix_([0, 2], [0, 2])] = block
    Q[np.ix_([1, 3], [1, 3])] = block
    return A, Q
