"""The reproductions ledger: docs/reproductions.md is what the claim files and the checked-in results
give, verdicts follow their rules, and a difference without a cause is refused."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pandas as pd
import pytest
import yaml

from quadest.aggregate import reproductions as ledger

ROOT = Path(__file__).resolve().parents[1]


def test_ledger_is_regenerated_from_the_checked_in_results():
    """The committed ledger equals a fresh generation: a result or claim changed without the
    ledger following (or a number typed into the ledger by hand) fails here."""
    fresh = ledger.generate(ROOT / "docs" / "claims", ROOT)
    assert (ROOT / "docs" / "reproductions.md").read_text(encoding="utf-8") == fresh


def test_every_results_file_a_claim_names_is_checked_in():
    """A claim read from a file that git ignores (a per-run table the budget keeps out) would pass
    here and fail in every clone: each must be tracked."""
    tracked = set(subprocess.run(["git", "ls-files", "results"], cwd=ROOT, capture_output=True, text=True,
                                 check=True).stdout.splitlines())  # fmt: skip
    for path in sorted((ROOT / "docs" / "claims").glob("*.yaml")):
        for claim in yaml.safe_load(path.read_text(encoding="utf-8"))["claims"]:
            if "measure" in claim:
                assert claim["measure"]["file"] in tracked, (path.name, claim["claim"])


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
            "p_holm": [0.01, 0.5, 0.2],
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
    }
    return {"claim": "c", "where": "Table 1", "source_value": "v", "command": "quadest", "measure": measure,
            "expect": expect, **extra}  # fmt: skip


@pytest.mark.parametrize(
    ("state", "pair", "expect", "verdict"),
    [
        ("x", "a - b", {"below": 0}, ledger.REPRODUCED),  # [-15, -5] % below 0
        ("y", "a - b", {"below": 0}, ledger.NOT_REPRODUCED),  # [-1, 5] % straddles 0
        ("x", "c - b", {"above": 10}, ledger.REPRODUCED),  # [20, 40] % above 10
        ("x", "c - b", {"above": 25}, ledger.NOT_REPRODUCED),  # low end 20 is not above 25
        ("y", "a - b", {"contains": 0}, ledger.REPRODUCED),
        ("x", "a - b", {"contains": 0}, ledger.NOT_REPRODUCED),
        ("x", "c - b", {"within": [15, 45]}, ledger.REPRODUCED),
        ("x", "c - b", {"within": [25, 45]}, ledger.NOT_REPRODUCED),  # low end 20 outside
        ("x", "c - b", {"within": [15, 35]}, ledger.NOT_REPRODUCED),  # high end 40 outside
    ],
)
def test_verdicts_follow_the_interval(table: Path, state, pair, expect, verdict):
    entry = ledger.build_entry(claim(state, expect, pair=pair, cause="known"), table, "t")
    assert entry.verdict == verdict


@pytest.mark.parametrize(("pair", "verdict"), [("a - b", ledger.REPRODUCED), ("c - b", ledger.NOT_REPRODUCED)])
def test_a_tested_claim_needs_its_corrected_p_below_the_level_too(table: Path, pair, verdict):
    """With a ``p`` column the CI rule is not enough: a - b lies below 0 with Holm p 0.01 and holds;
    c - b lies above 10 but with Holm p 0.2, as a ranking that shows no step there."""
    expect = {"below": 0} if pair == "a - b" else {"above": 10}
    entry = ledger.build_entry(claim("x", expect, pair=pair, cause="known"), table, "t")
    assert entry.verdict == ledger.REPRODUCED
    tested = claim("x", expect, pair=pair, cause="known")
    tested["measure"]["p"] = "p_holm"
    entry = ledger.build_entry(tested, table, "t")
    assert entry.verdict == verdict and "and p < 0.05" in entry.ours


def test_reading_is_scaled_with_its_interval(table: Path):
    entry = ledger.build_entry(claim("x", {"below": 0}), table, "t")
    assert entry.ours.startswith("-10 % [-15, -5]")


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
