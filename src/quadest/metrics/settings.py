"""The ``metrics`` config node: the time windows of the windowed measures (docs/metrics.md).

The windows are fractions of the job's duration, so one setting serves a 2 s test job and a 100 s
flight alike. They change no estimator result (the windowed measures are computed from the
per-step sums every result keeps), so the node is in no cache key (``docs/cache.md``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from quadest.errors import ConfigError


@dataclass
class MetricsConf:
    """``transient``: the first fraction of the steps, the transient window; ``steady``: the last
    fraction, the steady-state window; ``settle_factor``: a state has converged from the first time
    after which the RMS over the runs stays below ``settle_factor`` × its steady-state RMSE."""

    transient: float = 0.1
    steady: float = 0.5
    settle_factor: float = 2.0

    def check(self) -> None:
        """One-line errors naming the key before any work starts."""
        for key in ("transient", "steady"):
            value = getattr(self, key)
            if not (isinstance(value, int | float) and 0 < value <= 1):
                raise ConfigError(f"metrics.{key}", value, "must be a fraction of the steps in (0, 1]")
        factor = self.settle_factor
        if not (isinstance(factor, int | float) and math.isfinite(factor) and factor > 1):
            raise ConfigError("metrics.settle_factor", factor, "must be a finite number > 1")
