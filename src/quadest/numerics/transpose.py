"""The transpose of a stack of matrices, written once for every module that needs it."""

from __future__ import annotations

import numpy as np


def matrix_transpose(a: np.ndarray) -> np.ndarray:
    """``a`` (..., r, c) with its last two axes swapped (..., c, r): each matrix of a batch
    transposed, the leading batch axes kept (numpy 2's ``np.matrix_transpose``, which numpy 1.26
    lacks). A view, not a copy."""
    return np.swapaxes(a, -1, -2)
