"""The Joseph-form covariance update of the linearized Kalman filters (``mekf``, ``hf``), batched.

Bucy & Joseph 1968; Solà 2017 ("Quaternion kinematics for the error-state Kalman filter",
arXiv:1711.02508) eq. 276; filterpy's ``KalmanFilter.update``.
"""

from __future__ import annotations

import numpy as np


def joseph_covariance(P: np.ndarray, H: np.ndarray, R: np.ndarray, K: np.ndarray) -> np.ndarray:
    """``P⁺ = (I − K H) P (I − K H)ᵀ + K R Kᵀ`` for ``P`` (B, n, n), ``H`` (B, m, n), ``R`` (m, m)
    and any gain ``K`` (B, n, m).

    The covariance of ``(I − K H) e − K v`` for independent ``e ~ (0, P)`` and ``v ~ (0, R)``: right
    for every gain (not only the optimal one) and symmetric positive semi-definite by construction.
    """
    I_KH = np.eye(P.shape[-1]) - K @ H
    return I_KH @ P @ np.swapaxes(I_KH, -1, -2) + K @ R @ np.swapaxes(K, -1, -2)
