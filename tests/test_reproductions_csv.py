"""docs/reproductions.csv read as a reviewer's program would: every row's verdict is what its interval,
its rule and its test say, decided here from the CSV alone (not with the generator's code)."""

from __future__ import annotations

import csv
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
COLUMNS = ["source", "claim", "verdict", "estimate", "ci_low", "ci_high", "rule", "rule_low", "rule_high", "p",
           "runs", "runs_needed", "choice"]  # fmt: skip
CLASSES = ("reproduced", "contradicted", "inconclusive", "not comparable", "not testable")


def rows() -> list[dict]:
    with (ROOT / "docs" / "reproductions.csv").open(encoding="utf-8", newline="") as handle:
        reader = csv.DictReader(handle)
        assert reader.fieldnames == COLUMNS
        return list(reader)


def expected(row: dict) -> str:
    """The verdict the row's numbers give: the CI wholly on the claim's side (and p < 0.05 when the
    row has a test) is reproduced, wholly on the other side contradicted, anything else inconclusive."""
    low, high, rule = float(row["ci_low"]), float(row["ci_high"]), row["rule"]
    lo = float(row["rule_low"]) if row["rule_low"] else None
    hi = float(row["rule_high"]) if row["rule_high"] else None
    if rule == "below":
        claim_side, other_side = high < hi, low >= hi
    elif rule == "above":
        claim_side, other_side = low > lo, high <= lo
    elif rule == "contains":
        claim_side = low <= lo <= high
        other_side = not claim_side
    else:
        claim_side, other_side = lo <= low and high <= hi, high < lo or low > hi
    if other_side:
        return "contradicted"
    if claim_side and (not row["p"] or float(row["p"]) < 0.05):
        return "reproduced"
    return "inconclusive"


@pytest.mark.parametrize("row", rows(), ids=lambda r: f"{r['source']}:{r['claim'][:40]}")
def test_every_rows_verdict_is_what_its_interval_and_rule_say(row: dict):
    assert row["verdict"] in CLASSES
    if not row["estimate"]:
        # a claim nothing here can hold, or one (or a reading of one) that no checked-in run decides
        assert row["verdict"] in ("not testable", "inconclusive")
        return
    assert float(row["ci_low"]) <= float(row["ci_high"])
    fields = {"below": ("rule_high",), "above": ("rule_low",)}.get(row["rule"], ("rule_low", "rule_high"))
    assert row["rule"] in ("below", "above", "within", "contains", "equivalent")
    assert all(row[f] for f in fields) and not any(row[f] for f in {"rule_low", "rule_high"} - set(fields))
    if row["rule"] == "contains":
        assert row["rule_low"] == row["rule_high"]
    assert row["verdict"] == expected(row)
    if row["runs_needed"]:
        assert row["verdict"] == "inconclusive" and int(row["runs_needed"]) > int(row["runs"])


def test_the_header_counts_each_class_of_the_table():
    """The Markdown header's counts are the verdicts of its rows (one per claim)."""
    text = (ROOT / "docs" / "reproductions.md").read_text(encoding="utf-8")
    header = re.search(r"^(\d+) claims: (.*)\.$", text, re.MULTILINE)
    counts = dict((name, int(n)) for n, name in re.findall(r"(\d+) ([a-z ]+?)(?:,|$)", header.group(2)))
    assert tuple(counts) == CLASSES
    table = [line for line in text.splitlines() if line.startswith("| ") and not line.startswith("| claim |")]
    for name in CLASSES:
        assert sum(line.rstrip(" |").split(" | ")[-2] == f"**{name}**" for line in table) == counts[name], name
    assert sum(counts.values()) == int(header.group(1)) == len(table)
    claims = {(r["source"], r["claim"]) for r in rows()}
    assert len(claims) == len(table)
