"""What a further sensor delivers to the filters: its samples and when they are available."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class SensorRecord:
    """The samples of one further sensor: ``values`` (B, K+1, m_s) and ``available`` (K+1,) bool
    (its rate, dropouts). The model's ``sensors[name]`` describes how the filters use it."""

    values: np.ndarray
    available: np.ndarray
