"""The reproductions ledger: docs/reproductions.md is what the claim files and the checked-in results
give, verdicts follow their rules, and a difference without a cause is refused."""

from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

from quadest.aggregate import reproductions as ledger
from quadest.aggregate import verdicts
from quadest.aggregate.reproductions_render import render_markdown

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.hygiene
def test_ledger_is_regenerated_from_the_checked_in_results():
    """The committed ledger and its CSV equal a fresh generation: a result or claim changed without
    the ledger following (or a number typed into the ledger by hand) fails here."""
    markdown, table = ledger.generate(ROOT / "docs" / "claims", ROOT)
    assert (ROOT / "docs" / "reproductions.md").read_text(encoding="utf-8") == markdown
    assert (ROOT / "docs" / "reproductions.csv").read_text(encoding="utf-8") == table


@pytest.mark.hygiene
def test_every_results_file_a_claim_names_is_checked_in():
    """A claim read from a file that git ignores (a per-run table the budget keeps out) would pass
    here and fail in every clone: each must be tracked."""
    tracked = set(subprocess.run(["git", "ls-files", "results"], cwd=ROOT, capture_output=True, text=True,
                                 check=True).stdout.splitlines())  # fmt: skip
    for path in sorted((ROOT / "docs" / "claims").glob("*.yaml")):
        for claim in yaml.safe_load(path.read_text(encoding="utf-8"))["claims"]:
            if "measure" in claim:
                assert claim["measure"]["file"] in tracked, (path.name, claim["claim"])


@pytest.mark.hygiene
def test_readme_links_the_ledger():
    assert "docs/reproductions.md" in (ROOT / "README.md").read_text(encoding="utf-8")


@pytest.fixture()
def table(tmp_path: Path) -> Path:
    """A results CSV with known estimates and intervals."""
    frame = pd.DataFrame(
        {
            "pair": ["a - b", "a - b", "c - b"],
            "state": ["x", "y", "x"],
            "rel_diff": [-0.10, 0.02, 0.30],
            "rel_ci_low": [-0.15, -0.01, 0.20],
            "rel_ci_high": [-0.05, 0.05, 0.40],
            "p_raw": [0.01, 0.04, 0.2],
            "runs": [40, 40, 40],
        }
    )
    (tmp_path / "results").mkdir()
    frame.to_csv(tmp_path / "results" / "paired.csv", index=False)
    return tmp_path


def claim(state: str, expect: dict, pair: str = "a - b", **extra) -> dict:
    measure = {
        "file": "results/paired.csv",
        "select": {"pair": pair, "state": state},
        "value": "rel_diff",
        "ci": ["rel_ci_low", "rel_ci_high"],
        "scale": 100,
        "unit": "%",
        "runs": "runs",
    }
    return {"claim": "c", "where": "Table 1", "source_value": "v", "command": "quadest", "measure": measure,
            "expect": expect, **extra}  # fmt: skip


@pytest.mark.parametrize(
    ("state", "pair", "expect", "verdict"),
    [
        ("x", "a - b", {"below": 0}, verdicts.REPRODUCED),  # [-15, -5] % below 0
        ("y", "a - b", {"below": 0}, verdicts.INCONCLUSIVE),  # [-1, 5] % straddles 0
        ("x", "c - b", {"below": 0}, verdicts.CONTRADICTED),  # [20, 40] % wholly above 0
        ("x", "c - b", {"above": 10}, verdicts.REPRODUCED),  # [20, 40] % above 10
        ("x", "c - b", {"above": 25}, verdicts.INCONCLUSIVE),  # low end 20 is not above 25, high 40 is
        ("x", "a - b", {"above": 0}, verdicts.CONTRADICTED),  # [-15, -5] % wholly below 0
        ("y", "a - b", {"contains": 0}, verdicts.REPRODUCED),
        ("x", "a - b", {"contains": 0}, verdicts.CONTRADICTED),
        ("x", "c - b", {"within": [15, 45]}, verdicts.REPRODUCED),
        ("x", "c - b", {"within": [25, 45]}, verdicts.INCONCLUSIVE),  # low end 20 outside, estimate inside
        ("x", "c - b", {"within": [15, 35]}, verdicts.INCONCLUSIVE),  # high end 40 outside
        ("x", "c - b", {"within": [45, 60]}, verdicts.CONTRADICTED),  # wholly below the window
        ("y", "a - b", {"equivalent": [-10, 10]}, verdicts.REPRODUCED),  # [-1, 5] inside ±10 %
        ("y", "a - b", {"equivalent": [-1, 1]}, verdicts.INCONCLUSIVE),  # high end 5 beyond the margin
        ("x", "c - b", {"equivalent": [-1, 1]}, verdicts.CONTRADICTED),  # [20, 40] wholly outside ±1 %
    ],
)
def test_verdicts_follow_the_interval(table: Path, state, pair, expect, verdict):
    entry = ledger.build_entry(claim(state, expect, pair=pair, cause="known"), table, "t")
    assert entry.verdict == verdict


def with_test(state: str, expect: dict, pair: str) -> dict:
    """A claim that names the raw Wilcoxon p column of the table as its test."""
    spec = claim(state, expect, pair=pair, cause="known")
    spec["measure"] |= {"p": "p_raw", "test": "wilcoxon"}
    return spec


@pytest.mark.parametrize(("pair", "verdict"), [("a - b", verdicts.REPRODUCED), ("c - b", verdicts.INCONCLUSIVE)])
def test_a_tested_claim_needs_its_corrected_p_below_the_level_too(table: Path, pair, verdict):
    """With a test the CI rule is not enough: a - b lies below 0 with p 0.01 and holds; c - b lies
    above 10 but with p 0.2, so it is undecided (not contradicted: the CI is on the claim's side)."""
    expect = {"below": 0} if pair == "a - b" else {"above": 10}
    assert ledger.build_entry(claim("x", expect, pair=pair, cause="known"), table, "t").verdict == verdicts.REPRODUCED
    entry = ledger.build_entry(with_test("x", expect, pair), table, "t")
    assert entry.verdict == verdict and "Holm p < 0.05" in render_markdown([("T", [entry])])


def test_holm_runs_over_the_sources_claims_in_a_job_not_over_every_pair(table: Path):
    """Two claims with raw p 0.01 and 0.04 in one job: Holm gives 2 × 0.01 = 0.02 and max(0.02, 0.04)
    = 0.04 (Holm 1979), both below 0.05, whatever the job's other pairs (c - b, p 0.2) hold. Holm over
    the table's three rows would give 0.03 and 0.08, and the second claim would fail."""
    first, second = with_test("x", {"below": 0}, "a - b"), with_test("y", {"above": -5}, "a - b")
    entries = ledger.build_entries([first, second], table, "s")
    assert [o.p for e in entries for o in e.outcomes] == pytest.approx([0.02, 0.04])
    assert [e.verdict for e in entries] == [verdicts.REPRODUCED, verdicts.REPRODUCED]
    alone = ledger.build_entries([second], table, "s")[0]
    assert alone.outcomes[0].p == pytest.approx(0.04)


def test_a_test_that_cannot_pass_at_its_run_count_is_refused(table: Path):
    """The exact two-sided Wilcoxon p on n pairs is at least 2 / 2^n: 0.0625 on 5 pairs, never below
    0.05; on 6 pairs (0.03125) the rule can pass and is accepted."""
    frame = pd.read_csv(table / "results" / "paired.csv")
    frame.assign(runs=5).to_csv(table / "results" / "paired.csv", index=False)
    with pytest.raises(ledger.ClaimError, match=r"^t 1: .*5 runs"):
        ledger.build_entry(with_test("x", {"below": 0}, "a - b"), table, "t")
    frame.assign(runs=6).to_csv(table / "results" / "paired.csv", index=False)
    assert ledger.build_entry(with_test("x", {"below": 0}, "a - b"), table, "t").verdict == verdicts.REPRODUCED


def test_runs_needed_follow_the_half_width_scaling(table: Path):
    """y: estimate 2 %, CI [-1, 5] % at 40 runs, rule below 0: the low end is 3 from the estimate and
    the estimate 2 from the bound, so the CI clears 0 (from the other side) at 40 (3 / 2)^2 = 90 runs;
    the CI already bounds any difference from 0 to 5 %."""
    entry = ledger.build_entry(claim("y", {"below": 0}, cause="known"), table, "t")
    assert entry.outcomes[0].decision.runs_needed == 90
    assert entry.outcomes[0].decision.effect_bound == pytest.approx(5.0)


def test_a_claim_no_run_decides_is_inconclusive(table: Path):
    spec = {"claim": "c", "where": "§1", "source_value": "v", "needs": "a run with 3 beacons"}
    entry = ledger.build_entry(spec, table, "t")
    assert entry.verdict == verdicts.INCONCLUSIVE and entry.cause == "a run with 3 beacons"


def test_readings_that_disagree_make_a_claim_not_comparable(table: Path):
    one, other = claim("x", {"below": 0}), claim("x", {"below": 0}, pair="c - b")
    spec = {**claim("x", {"below": 0}, cause="known"), "choice": "the truth"}
    for key in ("command", "measure"):
        spec.pop(key)
    spec["readings"] = [{"reading": "A", "command": "q", "measure": one["measure"]},
                        {"reading": "B", "command": "q", "measure": other["measure"]}]  # fmt: skip
    assert ledger.build_entry(spec, table, "t").verdict == verdicts.NOT_COMPARABLE
    spec["readings"][1] = {"reading": "B", "command": "q", "measure": one["measure"]}
    assert ledger.build_entry(spec, table, "t").verdict == verdicts.REPRODUCED
    spec["readings"][1] = {"reading": "B", "why": "needs a flight in the tutorial's domain"}
    assert ledger.build_entry(spec, table, "t").verdict == verdicts.INCONCLUSIVE


def test_a_negative_scale_keeps_the_interval_ordered(table: Path):
    """Reading a - b (CI [-15, -5] %) as b - a with scale -100 gives 10 % [5, 15]: the ends swap with the sign."""
    spec = claim("x", {"above": 0})
    spec["measure"]["scale"] = -100
    reading = ledger.build_entry(spec, table, "t").outcomes[0].reading
    assert (reading.low, reading.value, reading.high) == pytest.approx((5.0, 10.0, 15.0))


def test_reading_is_scaled_with_its_interval(table: Path):
    entry = ledger.build_entry(claim("x", {"below": 0}), table, "t")
    assert render_markdown([("T", [entry])]).count("-10 % [-15, -5]") == 1


def test_not_reproduced_without_a_cause_is_refused(table: Path):
    with pytest.raises(ledger.ClaimError, match="cause"):
        ledger.build_entry(claim("y", {"below": 0}), table, "t")


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"measure": {"file": "results/paired.csv", "select": {"pair": "a - b"}, "value": "rel_diff"}}, "2 rows"),
        ({"measure": {"file": "results/none.csv", "value": "rel_diff"}}, "does not exist"),
        ({"measure": {"file": "results/paired.csv", "select": {"pair": "a - b", "state": "x"}, "value": "p"}}, "p"),
        ({"expect": {"less": 0}}, "expect must be one of"),
        ({"expect": {"within": [5, 1]}}, "low < high"),
        (
            {"measure": {"file": "results/paired.csv", "select": {"pair": "c - b"}, "value": "rel_diff", "p": "p_raw"}},
            "needs measure.test",
        ),
        ({"choice": "x", "readings": [{"reading": "A", "why": "w"}]}, "at least two readings"),
        ({"needs": "a run"}, "'needs' names the run"),
        ({"colour": "red"}, "unknown key"),
        ({"testable": False, "why": ""}, "needs 'why'"),
    ],
)
def test_malformed_claims_are_refused(table: Path, change: dict, message: str):
    with pytest.raises(ledger.ClaimError, match=message):
        ledger.build_entry({**claim("x", {"below": 0}), **change}, table, "t")


def test_check_mode_reports_a_stale_ledger(table: Path, capsys):
    claims = table / "docs" / "claims"
    claims.mkdir(parents=True)
    (claims / "a.yaml").write_text(yaml.safe_dump({"title": "A", "claims": [claim("x", {"below": 0})]}))
    assert ledger.main(["--root", str(table), "--check"]) == 1
    assert ledger.main(["--root", str(table)]) == 0
    assert ledger.main(["--root", str(table), "--check"]) == 0
    (claims / "a.yaml").write_text(yaml.safe_dump({"title": "A", "claims": [claim("y", {"below": 0})]}))
    assert ledger.main(["--root", str(table)]) == 2
    assert "cause" in capsys.readouterr().err


@pytest.mark.parametrize("runs", range(3, 11))
def test_the_smallest_wilcoxon_p_is_scipys_exact_one(runs: int):
    """All n differences of one sign give the exact two-sided signed-rank p its minimum, which the
    refusal rule assumes is 2 / 2^n."""
    from scipy.stats import wilcoxon

    assert verdicts.minimum_p("wilcoxon", runs) == pytest.approx(wilcoxon(np.arange(1.0, runs + 1)).pvalue, rel=1e-12)


@pytest.mark.parametrize("width", [1e-3, 1e-8, 2e-11])
def test_a_narrow_window_prints_its_ends_and_the_value_apart(width: float):
    """A published value held to round-off (a window of ± width relative) prints with the digits that
    tell the window's ends and our value apart, not the three digits of the other rows."""
    printed = 0.03463604419042699
    low, high = printed * (1 - width), printed * (1 + width)
    rule = verdicts.Rule("within", low, high)
    text = rule.text()
    ends = text[text.index("[") + 1 : text.index("]")].split(", ")
    assert float(ends[0]) != float(ends[1])
    assert float(ends[0]) <= low * (1 + width / 10) and float(ends[1]) >= high * (1 - width / 10)
    digits = rule.digits()
    assert len({f"{x:.{digits}g}" for x in (low, printed, high)}) == 3


def test_a_published_mean_falls_in_its_interval_as_often_as_its_confidence():
    """``measure.published``: on normal per-run values, a source's N_pub-run mean of the same quantity
    lies in ours ± t s √(1/N + 1/N_pub) with the stated probability (a prediction interval, exact for
    normal data). 4000 repetitions: the coverage's Monte Carlo error is 3·√(0.95·0.05/4000) ≈ 0.010."""
    rng = np.random.default_rng(7)
    n, n_pub, reps = 10, 4, 4000
    ours, theirs = rng.normal(1.0, 0.3, (reps, n)), rng.normal(1.0, 0.3, (reps, n_pub)).mean(axis=1)
    inside = 0
    for sample, printed in zip(ours, theirs, strict=True):
        row = pd.Series({"std": sample.std(ddof=1)})
        low, high = ledger.published_interval(sample.mean(), row, {"std": "std", "runs": n_pub}, n, 1.0, "t")
        inside += low <= printed <= high
    assert abs(inside / reps - 0.95) < 3 * np.sqrt(0.95 * 0.05 / reps)


def test_a_published_interval_widens_by_the_rounding_and_narrows_with_the_confidence():
    row = pd.Series({"std": 0.03})
    base = ledger.published_interval(0.114, row, {"std": "std", "runs": 100}, 1000, 1.0, "t")
    rounded = ledger.published_interval(0.114, row, {"std": "std", "runs": 100, "rounding": 5e-4}, 1000, 1.0, "t")
    assert rounded[1] - rounded[0] == pytest.approx(base[1] - base[0] + 1e-3)
    lower = ledger.published_interval(0.114, row, {"std": "std", "runs": 100, "confidence": 0.9}, 1000, 1.0, "t")
    assert lower[1] - lower[0] < base[1] - base[0]
    with pytest.raises(ledger.ClaimError, match="published needs std and runs"):
        ledger.published_interval(0.114, row, {"std": "std"}, 1000, 1.0, "t")
