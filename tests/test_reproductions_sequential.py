"""The ledger reads a runs=auto job's decisions.csv: its α-spending interval decides the claim as any
interval does, the row shows the runs it took and why it stopped, and the claims reading one job are
held to a Bonferroni level."""

from __future__ import annotations

import math
from pathlib import Path

import pandas as pd
import pytest
import yaml

from quadest.aggregate import reproductions as ledger
from quadest.aggregate import verdicts
from quadest.aggregate.reproductions_render import render_csv, render_markdown

DECISIONS = pd.DataFrame(
    {
        "pair": ["a - b", "a - b", "c - b"],
        "state": ["x", "y", "x"],
        "verdict": ["better", "equivalent", "undecided"],
        "runs": [150, 50, 400],
        "estimate": [-3.0, -0.02, 0.5],
        "ci_low": [-5.0, -0.07, -0.3],
        "ci_high": [-1.0, 0.03, 1.3],
        "margin": [0.1, 0.1, 0.1],
    }
)


@pytest.fixture()
def job(tmp_path: Path) -> Path:
    """A runs=auto job's folder: a synthetic decisions.csv and the config the job writes beside it."""
    folder = tmp_path / "results" / "auto"
    folder.mkdir(parents=True)
    DECISIONS.to_csv(folder / "decisions.csv", index=False)
    write_config(folder, alpha=0.05)
    return tmp_path


def write_config(folder: Path, alpha: float) -> None:
    config = {"runs": "auto", "decision": {"batch": 50, "max_runs": 400, "alpha": alpha, "margin": 0.1}}
    (folder / "config.yaml").write_text(yaml.safe_dump(config), encoding="utf-8")


def claim(pair: str, state: str, expect: dict, **extra) -> dict:
    measure = {"file": "results/auto/decisions.csv", "select": {"pair": pair, "state": state}, "sequential": True}
    return {"claim": f"{pair} {state}", "where": "§1", "source_value": "v", "command": "quadest runs=auto",
            "measure": measure, "expect": expect, "cause": "known", **extra}  # fmt: skip


def test_a_decided_comparison_gives_the_verdict_its_interval_says(job: Path):
    """better with [-5, -1] % decides "below 0" as reproduced and "above 0" as contradicted, read from
    the columns of decisions.csv with the runs the job took."""
    entry = ledger.build_entry(claim("a - b", "x", {"below": 0}), job, "t")
    assert entry.verdict == verdicts.REPRODUCED
    reading = entry.outcomes[0].reading
    assert (reading.value, reading.low, reading.high, reading.runs) == (-3.0, -5.0, -1.0, 150)
    assert ledger.build_entry(claim("a - b", "x", {"above": 0}), job, "t").verdict == verdicts.CONTRADICTED


def test_the_row_shows_the_runs_and_that_the_interval_is_the_alpha_spending_one(job: Path):
    entry = ledger.build_entry(claim("a - b", "x", {"below": 0}), job, "t")
    text = render_markdown([("T", [entry])])
    assert "150 runs, α-spending interval (runs=auto at α = 0.05, at most 400 runs, margin ±0.1 %: better)" in text
    assert ",150," in render_csv([("T", [entry])]).splitlines()[1]


def test_an_equivalent_comparison_needs_no_more_runs(job: Path):
    """[-0.07, 0.03] % straddles 0 (a one-sided claim stays inconclusive) but lies inside ±0.1 %: the
    procedure stopped on equivalence, so the row gives the bound, not a run count."""
    entry = ledger.build_entry(claim("a - b", "y", {"below": 0}), job, "t")
    decision = entry.outcomes[0].decision
    assert entry.verdict == verdicts.INCONCLUSIVE
    assert decision.runs_needed is None
    assert "equivalent" in decision.reason and "±0.1 %" in decision.reason
    assert decision.effect_bound == pytest.approx(0.07)


def test_an_undecided_comparison_gives_the_runs_beyond_the_budget(job: Path):
    """[-0.3, 1.3] % around 0.5 %: the lower half-width 0.8 clears 0 at ⌈400 (0.8 / 0.5)²⌉ runs."""
    entry = ledger.build_entry(claim("c - b", "x", {"above": 0}), job, "t")
    decision = entry.outcomes[0].decision
    assert entry.verdict == verdicts.INCONCLUSIVE
    assert decision.runs_needed == math.ceil(400 * (0.8 / 0.5) ** 2)
    assert "undecided at the budget of 400 runs" in decision.reason


def test_claims_reading_one_job_are_held_to_a_bonferroni_level(job: Path):
    """Two comparisons from one job at α = 0.05 each would hold together only at 0.10: refused; at
    α = 0.025 accepted. Two claims reading the same comparison count once."""
    two = [claim("a - b", "x", {"below": 0}), claim("c - b", "x", {"above": 0})]
    with pytest.raises(ledger.ClaimError, match=r"decision.alpha <= 0.05/2"):
        ledger.build_entries(two, job, "t")
    assert len(ledger.build_entries([two[0], claim("a - b", "x", {"above": -10})], job, "t")) == 2
    write_config(job / "results" / "auto", alpha=0.025)
    assert [e.verdict for e in ledger.build_entries(two, job, "t")] == [verdicts.REPRODUCED, verdicts.INCONCLUSIVE]


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"value": "estimate"}, "drop \\['value'\\]"),
        ({"p": "p", "test": "wilcoxon"}, "drop \\['p', 'test'\\]"),
    ],
)
def test_a_sequential_measure_takes_no_columns_of_its_own(job: Path, change: dict, message: str):
    spec = claim("a - b", "x", {"below": 0})
    spec["measure"].update(change)
    with pytest.raises(ledger.ClaimError, match=message):
        ledger.build_entry(spec, job, "t")


def test_a_sequential_measure_needs_a_runs_auto_job(job: Path):
    folder = job / "results" / "auto"
    (folder / "config.yaml").write_text(yaml.safe_dump({"runs": 50}), encoding="utf-8")
    with pytest.raises(ledger.ClaimError, match="not a runs=auto job"):
        ledger.build_entry(claim("a - b", "x", {"below": 0}), job, "t")
