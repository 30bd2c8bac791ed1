"""The caption printed above every job's RMSE table (and written above it in ``rmse_table.md``):
one builder for the open loop, the closed loop and the flight-log replay.

A caption is the job kind's own first line, then the PCRLB line, then any lines of the kind's own.
The PCRLB line says what the table's PCRLB column is (:func:`~quadest.evaluation.pcrlb.pcrlb_caption`)
or why it is left out. When the table has smoothed rows (any smoother: fixed interval or fixed lag)
and a PCRLB column, it also says that the column is the *filtering* bound: a smoother uses later
measurements too, so its own bound is lower (Tichavský, Muravchik & Nehorai 1998 give the
filtering recursion) and a smoothed row may go below the column.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from quadest.evaluation.pcrlb import pcrlb_caption
from quadest.montecarlo.results import EstimatorResult


def has_smoothed_rows(results: Sequence[EstimatorResult]) -> bool:
    """Whether the table of ``results`` (one per estimator) has a smoothed row."""
    return any(result.smoothed is not None for result in results)


def table_caption(
    head: str,
    model_name: str,
    results: Sequence[EstimatorResult],
    pcrlb_left_out: str | None = None,
    tail: Sequence[str] = (),
    labels: Mapping[str, Any] | None = None,
) -> str:
    """The caption of a job's table: ``head``, the PCRLB line (``pcrlb_left_out``: the sentence
    saying why the job has no PCRLB column; else what the column is for data with these ``labels``,
    with the filtering-bound note when ``results`` have smoothed rows), then the lines of ``tail``."""
    smoothed = has_smoothed_rows(results)
    pcrlb = pcrlb_left_out if pcrlb_left_out is not None else pcrlb_caption(model_name, smoothed, labels)
    return "\n".join([head, pcrlb, *tail])
