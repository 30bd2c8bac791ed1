"""The ledger's five-way verdict: what a claim's confidence interval, its rule and its test say.

A claim's rule (``expect`` in a claim file) is one of

- ``{below: b}`` (the claim: the quantity is below ``b``), ``{above: b}``;
- ``{within: [lo, hi]}`` (a value in a window), ``{equivalent: [lo, hi]}`` (a tie: the difference
  lies inside the equivalence margin ``[lo, hi]``, read exactly as ``within``);
- ``{contains: x}`` (the quantity is ``x``: a printed value our interval should cover).

With our estimate and its 95 % confidence interval [low, high] the verdict is

- *reproduced*: the interval lies wholly on the claim's side (below ``b``, above ``b``, inside the
  window, or around ``x``) and, when the claim names a test, its Holm-corrected p is below 0.05;
- *contradicted*: the interval lies wholly on the other side (at or above ``b``, at or below ``b``,
  wholly outside the window, or away from ``x``);
- *inconclusive*: neither. The ledger then gives the number of runs the observed effect would need
  to decide, from the interval's half-width shrinking as 1/√n (the normal approximation every
  interval of the job outputs shares: Student t, Fieller): with n runs, an estimate at
  distance d from the nearest decision boundary and the half-width h of the interval on that side,
  the interval clears the boundary at n' = ⌈n (h / d)²⌉. When it is the test that fails (the interval
  is on the claim's side), n' is where the observed z-score, z ∝ √n, reaches the first Holm step,
  z = Φ⁻¹(1 − α / (2m)) for m tested claims. It also gives the bound the interval already sets: the
  quantity differs from ``b`` by at most max(|low − b|, |high − b|).

Multiplicity: the p-values of a job's pairs are raw two-sided test p-values; Holm's step-down
correction (Holm 1979, :func:`quadest.evaluation.paired.holm`) is applied over the claims of one
source in one job (:func:`holm_over_claims`), not over every pair the job computes.

A rule that cannot pass at the runs it has is refused (:func:`check_attainable`): the exact two-sided
Wilcoxon signed-rank p on n pairs is at least 2 / 2ⁿ (all differences of one sign), so on 5 pairs or
fewer it never falls below 0.05, with or without a correction.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.stats import norm

from quadest.evaluation.paired import SIGNIFICANCE, holm
from quadest.evaluation.sequential import EQUIVALENT

REPRODUCED = "reproduced"
CONTRADICTED = "contradicted"
INCONCLUSIVE = "inconclusive"
NOT_COMPARABLE = "not comparable"
NOT_TESTABLE = "not testable"
VERDICTS = (REPRODUCED, CONTRADICTED, INCONCLUSIVE, NOT_COMPARABLE, NOT_TESTABLE)
RULE_KINDS = ("below", "above", "within", "equivalent", "contains")
TESTS = ("wilcoxon", "ttest")


class RuleError(ValueError):
    """A rule that is malformed or cannot decide (the caller adds the claim's name)."""


@dataclass(frozen=True)
class Rule:
    """A claim's rule: ``kind`` and its bounds, as the CSV's ``rule_low``/``rule_high`` columns."""

    kind: str
    low: float | None
    high: float | None

    @classmethod
    def parse(cls, expect: object) -> Rule:
        """The rule of a claim file's ``expect`` mapping (one key of :data:`RULE_KINDS`)."""
        if not isinstance(expect, dict) or len(expect) != 1 or next(iter(expect)) not in RULE_KINDS:
            raise RuleError(f"expect must be one of {{{', '.join(RULE_KINDS)}}}, got {expect}")
        kind, bound = next(iter(expect.items()))
        if kind in ("within", "equivalent"):
            if not isinstance(bound, list) or len(bound) != 2 or float(bound[0]) >= float(bound[1]):
                raise RuleError(f"expect.{kind} must be a window [low, high] with low < high, got {bound}")
            return cls(kind, float(bound[0]), float(bound[1]))
        value = float(bound)
        return cls(kind, value if kind in ("above", "contains") else None, value if kind != "above" else None)

    def boundaries(self) -> list[float]:
        """The values where the verdict can change."""
        return sorted({b for b in (self.low, self.high) if b is not None})

    def digits(self) -> int:
        """Significant digits that tell a window's two ends apart (at least 3, :func:`fmt`'s default):
        a window of a printed value ± round-off needs about as many digits as the value was printed with."""
        if self.kind not in ("within", "equivalent") or self.low == self.high:
            return 3
        scale = max(abs(self.low), abs(self.high))
        return max(3, math.ceil(math.log10(scale / (self.high - self.low))) + 2)

    def text(self) -> str:
        d = self.digits()
        if self.kind in ("within", "equivalent"):
            what = self.kind if self.kind == "within" else "within the margin"
            return f"CI {what} [{self.low:.{max(d, 6)}g}, {self.high:.{max(d, 6)}g}]"
        return f"CI {self.kind} {(self.high if self.kind == 'below' else self.low):g}"


def side(low: float, high: float, rule: Rule) -> str:
    """``"claim"`` when [low, high] lies wholly on the claim's side of ``rule``, ``"other"`` when wholly
    on the other side, ``"neither"`` otherwise (also for a NaN end)."""
    if math.isnan(low) or math.isnan(high):
        return "neither"
    if rule.kind == "below":
        return "claim" if high < rule.high else "other" if low >= rule.high else "neither"
    if rule.kind == "above":
        return "claim" if low > rule.low else "other" if high <= rule.low else "neither"
    if rule.kind == "contains":
        return "claim" if low <= rule.low <= high else "other"
    if rule.low <= low and high <= rule.high:
        return "claim"
    return "other" if high < rule.low or low > rule.high else "neither"


@dataclass(frozen=True)
class Decision:
    """A verdict with what it rests on: the runs that would decide it, and the bound the CI sets."""

    verdict: str
    runs_needed: int | None = None
    effect_bound: float | None = None
    reason: str = ""


def decide(value: float, low: float, high: float, rule: Rule, *, p: float | None = None, p_raw: float | None = None,
           family: int = 1, runs: int | None = None) -> Decision:  # fmt: skip
    """The verdict of one reading (see the module docstring): ``p`` is the Holm-corrected p of the
    claim's test (None without one), ``p_raw`` its raw p, ``family`` the number of claims Holm ran over."""
    where = side(low, high, rule)
    if where == "other":
        return Decision(CONTRADICTED)
    if where == "claim" and (p is None or p < SIGNIFICANCE):
        return Decision(REPRODUCED)
    if where == "claim":
        needed = None
        if runs and p_raw is not None and 0 < p_raw < 1:
            z_needed, z_seen = norm.ppf(1 - SIGNIFICANCE / (2 * family)), norm.ppf(1 - p_raw / 2)
            needed = math.ceil(runs * (z_needed / z_seen) ** 2) if z_seen > 0 else None
        return Decision(INCONCLUSIVE, needed, None, f"the CI is on the claim's side, but Holm p = {p:.3g} ≥ 0.05")
    return Decision(INCONCLUSIVE, runs_to_decide(value, low, high, rule, runs), effect_bound(low, high, rule))


def with_sequential(decision: Decision, verdict: str, margin: float, max_runs: int) -> Decision:
    """An inconclusive reading of a ``runs=auto`` comparison (:mod:`quadest.evaluation.sequential`)
    says why it stopped: *equivalent* (its interval lies inside ±``margin`` %: no more runs are
    needed, any difference is below the margin), or *undecided* at the budget (the runs the observed
    effect would need, beyond ``max_runs``)."""
    if decision.verdict != INCONCLUSIVE:
        return decision
    if verdict == EQUIVALENT:
        reason = f"runs=auto decided equivalent: the interval lies inside ±{margin:g} %, any difference is smaller"
        return Decision(INCONCLUSIVE, None, decision.effect_bound, reason)
    reason = f"undecided at the budget of {max_runs} runs"
    return Decision(INCONCLUSIVE, decision.runs_needed, decision.effect_bound, reason)


def runs_to_decide(value: float, low: float, high: float, rule: Rule, runs: int | None) -> int | None:
    """⌈n (h / d)²⌉: the runs at which the CI, shrinking as 1/√n, clears the boundary nearest the
    estimate (None without a run count, a finite CI or a nonzero distance)."""
    if not runs or math.isnan(low) or math.isnan(high) or rule.kind == "contains":
        return None
    edge = min(rule.boundaries(), key=lambda b: abs(value - b))
    distance, half_width = abs(value - edge), (high - value if edge > value else value - low)
    if distance == 0 or half_width <= 0:
        return None
    return math.ceil(runs * (half_width / distance) ** 2)


def effect_bound(low: float, high: float, rule: Rule) -> float | None:
    """For a one-sided rule at ``b``: the largest distance from ``b`` the CI allows, max(|low − b|, |high − b|)."""
    if rule.kind not in ("below", "above") or math.isnan(low) or math.isnan(high):
        return None
    bound = rule.high if rule.kind == "below" else rule.low
    return max(abs(low - bound), abs(high - bound))


def minimum_p(test: str, runs: int) -> float:
    """The smallest two-sided p the test can give on ``runs`` pairs: 2 / 2ⁿ for the exact Wilcoxon
    signed-rank test (every difference of one sign), 0 for the t-test."""
    if test not in TESTS:
        raise RuleError(f"measure.test must be one of {list(TESTS)}, got {test!r}")
    return 2.0 / 2.0**runs if test == "wilcoxon" else 0.0


def check_attainable(test: str, runs: int, family_minimum: float, family: int) -> None:
    """Raise :class:`RuleError` when the claim's Holm-corrected p cannot fall below 0.05 at ``runs``:
    it is at least its own test's minimum p, and at least ``family`` times the smallest p any claim of
    its family can reach (Holm's first step)."""
    floor = max(minimum_p(test, runs), family * family_minimum)
    if floor >= SIGNIFICANCE:
        raise RuleError(
            f"a two-sided {test} test on {runs} runs (Holm over {family} claims) cannot give p < {SIGNIFICANCE}: "
            f"its smallest p is {floor:.3g}; decide it by the CI alone, or with more runs"
        )


def holm_over_claims(p_raw: list[float]) -> list[float]:
    """Holm-corrected p-values over one family of claims (their raw p, in order)."""
    return [float(x) for x in holm(np.asarray(p_raw, dtype=float))]
