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


def fresh_process_runs(script: str, fresh_cache: bool = True) -> list[dict]:
    """The JSON line ``script`` prints, from two fresh processes sharing an empty numba cache
    directory of their own: the first compiles the kernels it calls, the second loads them.
    ``fresh_cache=False`` (the scripts' quick mode) runs one process on the existing cache, given
    as both: the script is exercised, the compile time is not measured."""
    with tempfile.TemporaryDirectory() as cache:
        env = {**os.environ, KERNELS_ENV: "numba"}
        if fresh_cache:
            env["NUMBA_CACHE_DIR"] = cache
        return [
            json.loads(subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True,
                                      check=True).stdout)
            for _ in range(2 if fresh_cache else 1)
        ] * (1 if fresh_cache else 2)  # fmt: skip
