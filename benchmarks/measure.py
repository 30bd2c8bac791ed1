"""What the benchmark scripts share: best-of wall times and the compile and cached-load times of
numba kernels in fresh processes."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable

from quadest.numerics.square_root import KERNELS_ENV


def best_us(fun: Callable[[], object], repeats: int = 50, blocks: int = 5) -> float:
    """Best mean wall time of ``fun()`` over ``blocks`` blocks of ``repeats`` calls, in µs (after
    one untimed call)."""
    fun()
    best = float("inf")
    for _ in range(blocks):
        start = time.perf_counter()
        for _ in range(repeats):
            fun()
        best = min(best, (time.perf_counter() - start) / repeats * 1e6)
    return best


def fresh_process_runs(script: str) -> list[dict]:
    """The JSON line ``script`` prints, from two fresh processes sharing an empty numba cache
    directory of their own: the first compiles the kernels it calls, the second loads them."""
    with tempfile.TemporaryDirectory() as cache:
        env = {**os.environ, "NUMBA_CACHE_DIR": cache, KERNELS_ENV: "numba"}
        return [
            json.loads(subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True,
                                      check=True).stdout)
            for _ in range(2)
        ]  # fmt: skip
