"""The group-sequential procedure of ``runs=auto`` (:mod:`quadest.evaluation.sequential`), as a
pure function on synthetic paired samples whose true relative difference is known:

- the O'Brien–Fleming-type spending function has Lan & DeMets's published values;
- under no effect it decides *better* or *worse* in at most α = 5 % of many repetitions (the
  tolerance: the binomial quantile of that many repetitions at 5 %);
- a known 10 % difference is decided *worse* by the look computed in advance from the interval's
  formula;
- the job loop (:func:`quadest.app.sequential_runs.decide`) stops at the first look at which every
  comparison is decided, and at the budget otherwise.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from quadest.app.schema import DecisionConf, ExperimentConf
from quadest.app.sequential_runs import decide
from quadest.evaluation.sequential import (
    BETTER,
    EQUIVALENT,
    UNDECIDED,
    WORSE,
    look_alphas,
    sequential_decisions,
    spent_alpha,
)

ALPHA, BATCH, MAX_RUNS, MARGIN = 0.05, 50, 500, 1.0
SHAPE, SCALE = 4.0, 0.25  # the reference's per-run RMSE ~ Gamma(4, 0.25): mean 1, variance 0.25


def _samples(rng: np.random.Generator, effect: float, sigma: float, reps: int) -> tuple[np.ndarray, np.ndarray]:
    """(MAX_RUNS, reps) paired per-run RMSEs: the reference R ~ Gamma, the estimator
    E = (1 + effect) R W with W = exp(σ z − σ²/2), E[W] = 1, independent of R: the true relative
    difference E[E − R] / E[R] is exactly ``effect``, and R and E are correlated as under common
    random numbers."""
    reference = rng.gamma(SHAPE, SCALE, (MAX_RUNS, reps))
    w = np.exp(sigma * rng.standard_normal((MAX_RUNS, reps)) - sigma**2 / 2)
    return (1.0 + effect) * reference * w - reference, reference


def test_spending_function_has_the_published_values():
    """Lan & DeMets (1983): α(1) = α; the O'Brien–Fleming type spends 2 − 2Φ(z_{α/2}/√t), at α = 0.05
    0.0056 at t = 0.5 (tabulated in Jennison & Turnbull 2000, ch. 7) and almost nothing early."""
    assert spent_alpha(1.0, ALPHA) == pytest.approx(ALPHA, rel=1e-12)
    assert spent_alpha(0.5, ALPHA) == pytest.approx(2 - 2 * stats.norm.cdf(1.959964 / np.sqrt(0.5)), rel=1e-6)
    assert float(spent_alpha(0.5, ALPHA)) == pytest.approx(0.0056, abs=5e-5)
    assert spent_alpha(0.0, ALPHA) == 0.0
    looks = np.arange(BATCH, MAX_RUNS + 1, BATCH)
    misses = look_alphas(looks, MAX_RUNS, ALPHA)
    assert (misses > 0).all() and misses.sum() == pytest.approx(ALPHA, rel=1e-12)


def test_no_effect_decides_a_sign_in_at_most_alpha_of_repetitions():
    """Two estimators whose errors have the same mean (true relative difference 0): the
    procedure may say *better* or *worse* in at most α of the repetitions. With R repetitions the
    count of such errors at a true rate of α exceeds the binomial (R, α) quantile at 1 − 1e-3 with
    probability ≤ 1e-3, so that quantile is the tolerance. (A fixed 95 % interval at each of the 10
    looks errs in about 19 % of them: Armitage, McPherson & Rowe 1969.)"""
    reps = 2000
    d, reference = _samples(np.random.default_rng(20260), 0.0, 0.1, reps)
    decisions = sequential_decisions(d, reference, BATCH, MAX_RUNS, ALPHA, MARGIN)
    wrong = int(np.isin(decisions.verdict, [BETTER, WORSE]).sum())
    assert wrong <= stats.binom.ppf(1 - 1e-3, reps, ALPHA)
    assert (decisions.verdict != "").all()


def _runs_needed(effect_pct: float, sd_pct: float, power_z: float) -> int:
    """The first look n_k at which ``effect − (t_{n−1, 1−Δα_k/2} + z_power) · sd/√n > 0``: the
    interval r̂ ± t·sd/√n then lies above 0 unless r̂ falls ``z_power`` standard errors below the
    effect. Δα_k from the spending function written out here (Lan & DeMets 1983)."""
    z = stats.norm.isf(ALPHA / 2)
    looks = np.arange(BATCH, MAX_RUNS + 1, BATCH)
    spent = 2 - 2 * stats.norm.cdf(z / np.sqrt(looks / MAX_RUNS))
    misses = np.diff(np.concatenate([[0.0], spent]))
    for n, miss in zip(looks, misses, strict=True):
        if effect_pct - (stats.t.isf(miss / 2, n - 1) + power_z) * sd_pct / np.sqrt(n) > 0:
            return int(n)
    raise AssertionError("the budget cannot decide this effect")


def test_a_ten_percent_difference_is_decided_by_the_look_computed_in_advance():
    """E = 1.1 R W: the true relative difference is +10 %. The interval's residuals
    e = E − R − 0.1 R = 1.1 R (W − 1) have the standard deviation
    sd_e = 1.1 √(E[R²] (e^{σ²} − 1)) (R, W independent), in % of E[R] = 1. By the look computed from
    it with a z of 3.09 (power 0.999 at that look alone), a repetition is decided *worse* unless it
    is among the binomial (R, 0.001) quantile at 1 − 1e-3 that are not; none is decided *better*."""
    sigma, reps = 0.2, 400
    sd_pct = 100 * 1.1 * np.sqrt((SHAPE * SCALE**2 + 1.0) * (np.exp(sigma**2) - 1))
    needed = _runs_needed(10.0, sd_pct, stats.norm.isf(1e-3))
    assert BATCH < needed < MAX_RUNS  # the case exercises looks after the first
    d, reference = _samples(np.random.default_rng(31), 0.1, sigma, reps)
    decisions = sequential_decisions(d, reference, BATCH, MAX_RUNS, ALPHA, MARGIN)
    late = int(((decisions.verdict != WORSE) | (decisions.runs > needed)).sum())
    assert late <= stats.binom.ppf(1 - 1e-3, reps, 1e-3)
    assert not (decisions.verdict == BETTER).any()


def test_identical_estimators_are_equivalent_at_the_first_look():
    """Differences within round-off of each other are zero: the interval is [0, 0]."""
    reference = np.random.default_rng(1).gamma(SHAPE, SCALE, (MAX_RUNS, 3))
    d = np.zeros_like(reference)
    decisions = sequential_decisions(d, reference, BATCH, MAX_RUNS, ALPHA, MARGIN)
    assert (decisions.verdict == EQUIVALENT).all() and (decisions.runs == BATCH).all()
    assert (decisions.low == 0).all() and (decisions.high == 0).all()


def _tidy(runs: np.ndarray, rmse: dict[str, np.ndarray], diverged: dict[str, np.ndarray]) -> pd.DataFrame:
    """A tidy metrics table (the columns :func:`decide` reads) of one state ``x``."""
    return pd.concat(
        pd.DataFrame({"estimator": name, "run": runs, "state": "x", "unit": "m", "quantity": "filter",
                      "rmse": values, "diverged": diverged.get(name, np.zeros(runs.size, bool))})
        for name, values in rmse.items()
    )  # fmt: skip


def _experiment(batch: int, max_runs: int) -> ExperimentConf:
    return ExperimentConf(
        runs="auto", estimator={"ref": {}, "twin": {}, "late": {}}, progress=False,
        decision=DecisionConf(batch=batch, max_runs=max_runs),
    )  # fmt: skip


def test_the_job_stops_at_the_first_look_where_every_comparison_is_decided():
    """``twin`` equals ``ref`` (decided at look 1); ``late`` is 10 % worse on every run but diverged
    in every run of the first two batches, so it has no usable run before look 3. The loop asks for
    exactly three batches and reports each comparison at the look that decided it."""
    batch, calls = 10, []
    reference = np.random.default_rng(2).gamma(SHAPE, SCALE, 100)

    def run_batch(first_run: int) -> pd.DataFrame:
        calls.append(first_run)
        runs = np.arange(first_run + batch)
        lost = runs < 2 * batch
        return _tidy(runs, {"ref": reference[runs], "twin": reference[runs], "late": 1.1 * reference[runs]},
                     {"late": lost})  # fmt: skip

    table, runs = decide(_experiment(batch, 100), run_batch)
    assert calls == [0, 10, 20] and runs == 30
    by_pair = table.set_index("pair")
    assert by_pair.loc["twin - ref", "verdict"] == EQUIVALENT and by_pair.loc["twin - ref", "runs"] == 10
    assert by_pair.loc["late - ref", "verdict"] == WORSE and by_pair.loc["late - ref", "runs"] == 10
    assert by_pair.loc["late - ref", "estimate"] == pytest.approx(10.0, rel=1e-12)


def test_a_comparison_that_never_decides_ends_undecided_at_the_budget():
    """Pure noise around no effect with a tiny budget: every batch of the budget runs, then
    *undecided* with the runs of the last look."""
    batch, calls = 5, []
    rng = np.random.default_rng(3)
    reference, noise = rng.gamma(SHAPE, SCALE, 20), rng.standard_normal(20)

    def run_batch(first_run: int) -> pd.DataFrame:
        calls.append(first_run)
        runs = np.arange(first_run + batch)
        return _tidy(runs, {"ref": reference[runs], "twin": reference[runs], "late": reference[runs] + noise[runs]}, {})

    table, runs = decide(_experiment(batch, 20), run_batch)
    assert calls == [0, 5, 10, 15] and runs == 20
    late = table.set_index("pair").loc["late - ref"]
    assert late["verdict"] == UNDECIDED and late["runs"] == 20
