"""Comparisons that run until they decide: a group-sequential design with α-spending.

A ``runs=auto`` job (``docs/experiments.md``) adds Monte Carlo runs in batches and looks at its
paired comparisons after each batch. Looking repeatedly at a growing sample and stopping as soon
as an interval excludes zero makes a fixed 95 % interval at every look miss far more often than
5 % (Armitage, McPherson & Rowe 1969, *J. R. Statist. Soc. A* 132, 235–244: about 19 % over 10
looks). The intervals here stay valid by **α-spending** (Lan & DeMets 1983, *Biometrika* 70,
659–663): look ``k`` after ``n_k`` of at most ``N`` runs uses the interval at level ``1 − Δα_k``
with

    α(t) = 2 − 2 Φ(z_{1−α/2} / √t)          (the O'Brien–Fleming-type spending function)
    Δα_k = α(n_k / N) − α(n_{k−1} / N),      n_0 = 0,

so ``Σ_k Δα_k = α(n_K / N) ≤ α``. By the union bound (Bonferroni), the probability that *any* of
the looks' intervals misses the true value is at most ``Σ_k Δα_k ≤ α``, whatever the correlation
between looks: the family of intervals is a confidence sequence at level ``1 − α``, and so is the
interval at whichever look the procedure stops, however it chooses to stop. (The union bound is
conservative: Lan & DeMets's boundaries, computed from the joint law of the looks, spend exactly α;
this design spends at most α and needs no recursive numerical integration.)

The statistic is the one of ``paired_comparison.csv`` (:mod:`quadest.evaluation.paired`): per run
``i`` the paired difference ``d_i = RMSE_E,i − RMSE_R,i`` of an estimator E and its reference R on
the same run (common random numbers), and the relative difference ``r = d̄ / R̄`` of the means, in %
of the reference (negative: E is more accurate). The interval at level ``1 − Δα`` is the
delta-method interval of a ratio of means (Cochran 1977, *Sampling Techniques*, 3rd ed., ch. 6: the
large-sample variance of the ratio estimator, from the sample residuals ``e_i = d_i − r̂ R_i``)::

    r̂ ± t_{n−1, 1−Δα/2} · s_e / (√n · R̄)

with ``s_e`` the sample standard deviation of the ``e_i`` and Student's quantile for n − 1 degrees
of freedom (:mod:`quadest.evaluation.intervals`; ``paired_comparison.csv`` uses the same interval
at 95 %).

Verdict of a comparison at a look (``margin`` m in %): *better* if the interval lies below 0,
*worse* if above 0, *equivalent* if it lies inside ``[−m, m]`` (the interval-inclusion form of equivalence testing,
Schuirmann 1987, *J. Pharmacokinet. Biopharm.* 15, 657–680), else none yet; *undecided* if none at the last look.
The sign takes precedence: an interval wholly on one side of 0 is *better* or *worse* even when it
also lies inside the margin (the estimate says how small the difference is). A comparison keeps
the verdict, the runs and the interval of the first look that decided it.

Guarantee: for each comparison, P(the verdict is *better* when E is not more accurate, or *worse*
when it is not less accurate, or *equivalent* when |r| > m) ≤ P(some look's interval misses r) ≤ α,
under the assumption that each look's interval has coverage at least ``1 − Δα_k`` (the
studentised ratio is close to Student's t: runs independent, a finite variance, and enough runs
per look for the central limit theorem; a batch of 50 is the default). Not corrected over the
several comparisons of a job: each one is at level α.

Round-off: a per-run difference below :data:`quadest.evaluation.paired.ROUND_OFF` times the
reference's RMSE counts as zero, as in the paired comparison, so filters equal in exact arithmetic
end *equivalent* with the interval [0, 0] at the first look.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import stats

from quadest.evaluation.intervals import ratio_and_half_width

BETTER, WORSE, EQUIVALENT, UNDECIDED = "better", "worse", "equivalent", "undecided"


def spent_alpha(fraction: np.ndarray | float, alpha: float) -> np.ndarray:
    """The O'Brien–Fleming-type spending function of Lan & DeMets (1983):
    ``α(t) = 2 − 2 Φ(z_{1−α/2} / √t)`` for ``t`` in (0, 1], 0 at ``t = 0``; ``α(1) = α``."""
    t = np.asarray(fraction, dtype=float)
    z = stats.norm.isf(alpha / 2.0)
    with np.errstate(divide="ignore"):
        return np.where(t > 0, 2.0 * stats.norm.sf(z / np.sqrt(np.maximum(t, 1e-300))), 0.0)


def look_alphas(look_runs: np.ndarray, max_runs: int, alpha: float) -> np.ndarray:
    """``Δα_k`` of looks after ``look_runs`` (increasing, ≤ ``max_runs``) runs: what each look's
    interval may miss by (module docstring); their sum is at most ``alpha``."""
    spent = spent_alpha(np.asarray(look_runs, dtype=float) / float(max_runs), alpha)
    return np.diff(np.concatenate([[0.0], spent]))


@dataclass(frozen=True)
class Interval:
    """The relative difference estimator − reference in % of the reference, per comparison
    (arrays over the comparisons), with its interval at one look's level."""

    estimate: np.ndarray
    low: np.ndarray
    high: np.ndarray


def relative_difference_interval(d: np.ndarray, reference: np.ndarray, miss: float) -> Interval:
    """The delta-method interval of ``r = d̄ / R̄`` (in %) at level ``1 − miss`` (module docstring).

    Args:
        d: (n, C) paired differences estimator − reference, per run and comparison (round-off
            already zeroed).
        reference: (n, C) the reference's per-run RMSE.
        miss: the look's ``Δα``.

    With every difference zero the estimate and interval are 0 (an identical twin, whatever the
    reference's RMSE); with fewer than two runs or a reference mean of 0 otherwise, NaN.
    """
    d, reference = np.atleast_2d(np.asarray(d, float)), np.atleast_2d(np.asarray(reference, float))
    if d.shape[0] < 2:
        nan = np.full(d.shape[1], np.nan)
        return Interval(nan, nan.copy(), nan.copy())
    ratio, half = ratio_and_half_width(d, reference, miss)
    zero = ~d.any(axis=0)
    estimate = np.where(zero, 0.0, 100.0 * ratio)
    half = np.where(zero, 0.0, 100.0 * half)
    return Interval(estimate, estimate - half, estimate + half)


def verdicts(low: np.ndarray, high: np.ndarray, margin: float) -> np.ndarray:
    """Each comparison's verdict from its interval ``[low, high]`` (in %): *better*, *worse*,
    *equivalent* (inside ``±margin``), or ``""`` (not decided at this look; NaN included)."""
    low, high = np.asarray(low, float), np.asarray(high, float)
    out = np.full(low.shape, "", dtype=object)
    out[(low >= -margin) & (high <= margin)] = EQUIVALENT
    out[high < 0] = BETTER
    out[low > 0] = WORSE
    return out


@dataclass
class Decisions:
    """The state of a job's comparisons over its looks (arrays over the comparisons): the verdict
    (``""`` while open), the runs of the look that decided it (or of the last look), and its
    estimate and interval."""

    verdict: np.ndarray
    runs: np.ndarray
    estimate: np.ndarray
    low: np.ndarray
    high: np.ndarray

    @classmethod
    def open(cls, comparisons: int) -> Decisions:
        nan = np.full(comparisons, np.nan)
        return cls(np.full(comparisons, "", dtype=object), np.zeros(comparisons, int), nan, nan.copy(), nan.copy())

    @property
    def settled(self) -> bool:
        """Whether every comparison has a verdict."""
        return bool((self.verdict != "").all())

    def look(self, interval: Interval, runs: np.ndarray, margin: float, last: bool) -> None:
        """Record one look: the open comparisons take this look's interval and verdict (at the
        ``last`` look, *undecided* when it decides nothing); decided ones keep theirs."""
        open_ = self.verdict == ""
        new = verdicts(interval.low, interval.high, margin)
        if last:
            new = np.where(new == "", UNDECIDED, new)
        self.verdict = np.where(open_, new, self.verdict)
        self.runs = np.where(open_, runs, self.runs)
        for name in ("estimate", "low", "high"):
            setattr(self, name, np.where(open_, getattr(interval, name), getattr(self, name)))


def sequential_decisions(
    d: np.ndarray, reference: np.ndarray, batch: int, max_runs: int, alpha: float, margin: float
) -> Decisions:
    """The procedure on samples given in advance (what a ``runs=auto`` job does as its runs come
    in): looks after ``batch``, ``2 batch``, … ``max_runs`` runs of the (``max_runs``, C) paired
    differences ``d`` and reference RMSEs, each at level ``1 − Δα_k``, until every comparison has
    a verdict (module docstring)."""
    looks = np.arange(batch, max_runs + 1, batch)
    misses = look_alphas(looks, max_runs, alpha)
    decisions = Decisions.open(np.atleast_2d(d).shape[1])
    for k, (n, miss) in enumerate(zip(looks, misses, strict=True)):
        interval = relative_difference_interval(d[:n], reference[:n], miss)
        decisions.look(interval, np.full(decisions.verdict.shape, n), margin, last=k == looks.size - 1)
        if decisions.settled:
            break
    return decisions
