"""Compiled (numba) ``f`` and ``h`` of the UNGM benchmark model (:class:`quadest.models.validation.UNGMModel`).

The numpy reference's expressions in the same order, point by point (Kitagawa 1987; Gordon,
Salmond & Smith 1993): ``f(x) = 0.5 x + 25 x / (1 + x²) + 8 cos(1.2 k)`` and ``h(x) = x² / 20``,
for points ``x`` (B, K, 1) of runs with ``c[b] = 8 cos(1.2 k_b)`` computed once per run by numpy.
The same IEEE operations in the same order give the reference's values bit for bit (numba does not
contract a product and a sum into a fused multiply-add unless asked to), which tests/test_kernels.py checks.
"""

from __future__ import annotations

import numpy as np
from numba import njit

_JIT = {"cache": True, "error_model": "numpy", "nogil": True}


@njit(**_JIT)
def ungm_f(x: np.ndarray, c: np.ndarray, out: np.ndarray) -> None:
    """``out[b, k, 0] = 0.5 x + 25 x / (1 + x²) + c[b]`` for ``x`` (B, K, 1)."""
    B, K, _ = x.shape
    for b in range(B):
        for k in range(K):
            v = x[b, k, 0]
            out[b, k, 0] = 0.5 * v + 25.0 * v / (1.0 + v * v) + c[b]


@njit(**_JIT)
def ungm_h(x: np.ndarray, out: np.ndarray) -> None:
    """``out[b, k, 0] = x² / 20`` for ``x`` (B, K, 1)."""
    B, K, _ = x.shape
    for b in range(B):
        for k in range(K):
            v = x[b, k, 0]
            out[b, k, 0] = v * v / 20.0
