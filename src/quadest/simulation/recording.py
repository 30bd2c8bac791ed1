"""What a data source read from a file gives: one recorded run (:class:`Recording`), whatever the
format (:mod:`quadest.simulation.recorded`, :mod:`quadest.simulation.euroc`)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class Recording:
    """One recorded run: ``time`` (K,), ``measurements`` (K, m), ``truth`` (K, n) or ``None``,
    ``inputs`` (K, nu) or ``None``, and ``notes`` on how it was read (labels of the job)."""

    time: np.ndarray
    measurements: np.ndarray
    truth: np.ndarray | None = None
    inputs: np.ndarray | None = None
    notes: Mapping[str, object] = field(default_factory=dict)
