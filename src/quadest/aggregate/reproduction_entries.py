"""The ledger's rows as data: our reading of a claim, each reading decided, and the row that holds them
(read by ``quadest.aggregate.reproductions``, written out by ``quadest.aggregate.reproductions_render``)."""

from __future__ import annotations

from dataclasses import dataclass

from quadest.aggregate import verdicts as v


@dataclass(frozen=True)
class Reading:
    """Our number for one claim: the estimate and its 95 % CI (equal to it when the value is exact)."""

    value: float
    low: float
    high: float
    unit: str
    p_raw: float | None = None
    test: str | None = None
    runs: int | None = None
    family: tuple = ()
    sequential: Sequential | None = None
    comparison: tuple = ()
    interval: str = ""
    """What the interval is when it is not our quantity's 95 % CI (``measure.published``)."""


@dataclass(frozen=True)
class Sequential:
    """A reading from a ``runs=auto`` job's ``decisions.csv``: the comparison's own verdict, its
    equivalence margin (%), and the job's budget and level (its α-spending interval is the reading's CI)."""

    verdict: str
    margin: float
    max_runs: int
    alpha: float


@dataclass(frozen=True)
class Outcome:
    """One reading of a claim, decided: ``reading`` is None for a reading not run (``why`` says what would run it)."""

    name: str
    command: str
    rule: v.Rule | None
    reading: Reading | None
    decision: v.Decision
    p: float | None = None
    family_size: int = 1
    why: str = ""


@dataclass(frozen=True)
class Entry:
    """One row of the ledger."""

    source: str
    claim: str
    where: str
    source_value: str
    choice: str
    outcomes: tuple[Outcome, ...]
    verdict: str
    cause: str
