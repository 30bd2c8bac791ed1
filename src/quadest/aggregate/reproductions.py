"""The ledger of reproduced claims, ``docs/reproductions.md``, generated from the checked-in results.

Every claim of a seed or a published table that quadest reproduces is one entry of a claim file
``docs/claims/<source>.yaml``: what the source says (its own printed value, typed from the source),
the command that made our result, and *how to read* our number from a checked-in CSV. Our numbers
are never typed: they are read here, from ``results/``, with their 95 % confidence interval, and
the verdict follows from the interval and the claim's ``expect`` rule:

- ``{below: b}``: reproduced when the whole CI lies below ``b``;
- ``{above: b}``: reproduced when the whole CI lies above ``b``;
- ``{within: [lo, hi]}``: reproduced when the whole CI lies inside ``[lo, hi]``;
- ``{contains: x}``: reproduced when the CI contains ``x``.

A measure may also name a column ``p`` holding a multiplicity-corrected p-value (the Holm-corrected
Wilcoxon p of a ranking, say): then the claim is reproduced only when, besides the CI rule,
``p < 0.05`` (:data:`SIGNIFICANCE`), so that a ranking claim rests on the same test the ranking does.

Anything else is *not reproduced*, and then the entry must give the ``cause`` we found for the
difference (a claim file without one is an error). A claim marked ``testable: false`` gives
``why`` instead and is listed as *not testable here*.

``python -m quadest.aggregate.reproductions`` (from the repository root) rewrites
``docs/reproductions.md``; ``--check`` only compares and exits 1 when the file is stale.
``tests/test_reproductions.py`` runs the check, so a regenerated result that changes a verdict
without the ledger following fails the suite.
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import dataclass
from pathlib import Path

import pandas as pd
import yaml

CLAIM_KEYS = {"claim", "where", "source_value", "command", "measure", "expect", "cause", "testable", "why"}
MEASURE_KEYS = {"file", "select", "value", "ci", "scale", "unit", "p"}
EXPECT_KINDS = ("below", "above", "within", "contains")
REPRODUCED, NOT_REPRODUCED, NOT_TESTABLE = "reproduced", "not reproduced", "not testable here"
SIGNIFICANCE = 0.05
"""The level a measure's ``p`` column must fall below for a reproduction."""


class ClaimError(ValueError):
    """A claim file that cannot be read into the ledger (the message names the file and the claim)."""


@dataclass(frozen=True)
class Reading:
    """Our number for one claim: the estimate and its 95 % CI (equal to it when the value is exact)."""

    value: float
    low: float
    high: float
    unit: str
    p: float | None = None


@dataclass(frozen=True)
class Entry:
    """One row of the ledger."""

    claim: str
    where: str
    source_value: str
    command: str
    ours: str
    verdict: str
    cause: str


def read_measure(measure: dict, root: Path, label: str) -> Reading:
    """Read ``measure`` (file, select, value, ci, scale, unit) from the CSV under ``root``."""
    unknown = set(measure) - MEASURE_KEYS
    if unknown:
        raise ClaimError(f"{label}: unknown measure key(s) {sorted(unknown)}; allowed: {sorted(MEASURE_KEYS)}")
    for key in ("file", "value"):
        if key not in measure:
            raise ClaimError(f"{label}: measure.{key} is required")
    path = root / measure["file"]
    if not path.is_file():
        raise ClaimError(f"{label}: measure.file {measure['file']} does not exist")
    table = pd.read_csv(path)
    rows = table
    for column, wanted in (measure.get("select") or {}).items():
        if column not in table.columns:
            raise ClaimError(f"{label}: select column {column!r} is not in {measure['file']}")
        rows = rows[rows[column].astype(str) == str(wanted)]
    if len(rows) != 1:
        raise ClaimError(f"{label}: select {measure.get('select')} matches {len(rows)} rows of {measure['file']}")
    row = rows.iloc[0]
    scale = float(measure.get("scale", 1.0))
    columns = [measure["value"], *(measure.get("ci") or [measure["value"]] * 2)]
    missing = [c for c in [*columns, *([measure["p"]] if "p" in measure else [])] if c not in table.columns]
    if missing:
        raise ClaimError(f"{label}: column(s) {missing} are not in {measure['file']}")
    value, low, high = (float(row[c]) * scale for c in columns)
    if scale < 0:
        low, high = high, low
    p = float(row[measure["p"]]) if "p" in measure else None
    return Reading(value, low, high, str(measure.get("unit", "")), p)


def verdict(reading: Reading, expect: dict, label: str) -> str:
    """:data:`REPRODUCED` when the CI satisfies ``expect`` (see the module docstring), else
    :data:`NOT_REPRODUCED`; a CI with a NaN end is never a reproduction."""
    if len(expect) != 1 or next(iter(expect)) not in EXPECT_KINDS:
        raise ClaimError(f"{label}: expect must be one of {{{', '.join(EXPECT_KINDS)}}}, got {expect}")
    (kind, bound), low, high = next(iter(expect.items())), reading.low, reading.high
    if kind == "below":
        holds = high < float(bound)
    elif kind == "above":
        holds = low > float(bound)
    elif kind == "within":
        holds = float(bound[0]) <= low and high <= float(bound[1])
    else:
        holds = low <= float(bound) <= high
    if reading.p is not None:
        holds = holds and reading.p < SIGNIFICANCE
    return REPRODUCED if holds else NOT_REPRODUCED


def format_number(x: float) -> str:
    """Three significant digits, as the tables of the job outputs."""
    if math.isnan(x):
        return "nan"
    return f"{x:.3g}"


def format_reading(reading: Reading) -> str:
    unit = f" {reading.unit}" if reading.unit else ""
    p = "" if reading.p is None else f", p = {format_number(reading.p)}"
    if reading.low == reading.high == reading.value:
        return f"{format_number(reading.value)}{unit}{p}"
    return f"{format_number(reading.value)}{unit} [{format_number(reading.low)}, {format_number(reading.high)}]{p}"


def expectation_text(expect: dict, tested: bool = False) -> str:
    kind, bound = next(iter(expect.items()))
    if kind == "within":
        text = f"CI within [{bound[0]}, {bound[1]}]"
    else:
        text = {"below": "CI below {}", "above": "CI above {}", "contains": "CI contains {}"}[kind].format(bound)
    return f"{text} and p < {SIGNIFICANCE}" if tested else text


def build_entry(claim: dict, root: Path, label: str) -> Entry:
    """Read one claim into a ledger row (our number, verdict and the cause of any difference)."""
    unknown = set(claim) - CLAIM_KEYS
    if unknown:
        raise ClaimError(f"{label}: unknown key(s) {sorted(unknown)}; allowed: {sorted(CLAIM_KEYS)}")
    for key in ("claim", "where", "source_value"):
        if not str(claim.get(key, "")).strip():
            raise ClaimError(f"{label}: '{key}' is required")
    if claim.get("testable", True) is False:
        if not str(claim.get("why", "")).strip():
            raise ClaimError(f"{label}: a claim with testable: false needs 'why'")
        return Entry(claim["claim"], claim["where"], str(claim["source_value"]), "-", "-", NOT_TESTABLE, claim["why"])
    for key in ("command", "measure", "expect"):
        if key not in claim:
            raise ClaimError(f"{label}: '{key}' is required (or testable: false with 'why')")
    reading = read_measure(claim["measure"], root, label)
    result = verdict(reading, claim["expect"], label)
    cause = str(claim.get("cause", "")).strip()
    if result != REPRODUCED and not cause:
        raise ClaimError(f"{label}: not reproduced ({format_reading(reading)}), so 'cause' is required")
    ours = f"{format_reading(reading)}; reproduced if {expectation_text(claim['expect'], reading.p is not None)}"
    return Entry(claim["claim"], claim["where"], str(claim["source_value"]), claim["command"], ours, result, cause)


def read_claim_file(path: Path, root: Path) -> tuple[str, list[Entry]]:
    """The title and the entries of one ``docs/claims/<source>.yaml``."""
    spec = yaml.safe_load(path.read_text(encoding="utf-8")) or {}
    if not spec.get("title") or not spec.get("claims"):
        raise ClaimError(f"{path.name}: needs 'title' and a non-empty 'claims' list")
    entries = [build_entry(claim, root, f"{path.name} claim {i + 1}") for i, claim in enumerate(spec["claims"])]
    return spec["title"], entries


def cell(text: str) -> str:
    """A Markdown table cell: one line, pipes escaped."""
    return " ".join(str(text).split()).replace("|", "\\|")


def render(sections: list[tuple[str, list[Entry]]]) -> str:
    """The whole ``docs/reproductions.md``."""
    counts = {
        v: sum(e.verdict == v for _, es in sections for e in es) for v in (REPRODUCED, NOT_REPRODUCED, NOT_TESTABLE)
    }
    lines = [
        "# Reproductions: every claim of a seed or a published table, and what our results say",
        "",
        "Generated by `python -m quadest.aggregate.reproductions` from the claim files in `docs/claims/` and",
        "the checked-in results; do not edit by hand (`tests/test_reproductions.py` regenerates and compares).",
        "The source's value is typed from the source; ours is read from the named results file, as the",
        "estimate with its 95 % confidence interval, and the verdict follows from the interval and the rule",
        "shown. Every verdict other than *reproduced* names the cause we found for the difference.",
        "",
        f"{sum(counts.values())} claims: {counts[REPRODUCED]} reproduced, {counts[NOT_REPRODUCED]} not reproduced, "
        f"{counts[NOT_TESTABLE]} not testable here.",
    ]
    header = "| claim | where | the source says | our command | ours (95 % CI) | verdict | cause of the difference |"
    for title, entries in sections:
        lines += ["", f"## {title}", "", header, "|---|---|---|---|---|---|---|"]
        for e in entries:
            command = f"`{e.command}`" if e.command != "-" else "-"
            row = (e.claim, e.where, e.source_value, command, e.ours, f"**{e.verdict}**", e.cause or "-")
            lines.append("| " + " | ".join(cell(x) for x in row) + " |")
    return "\n".join(lines) + "\n"


def generate(claims_dir: Path, root: Path) -> str:
    """The ledger from every ``*.yaml`` in ``claims_dir`` (sorted by file name) and the results under ``root``."""
    files = sorted(claims_dir.glob("*.yaml"))
    if not files:
        raise ClaimError(f"no claim files in {claims_dir}")
    return render([read_claim_file(path, root) for path in files])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m quadest.aggregate.reproductions", description=__doc__.split("\n")[0]
    )
    parser.add_argument("--root", type=Path, default=Path("."), help="the repository root (default: .)")
    parser.add_argument("--check", action="store_true", help="only compare with the ledger on disk; exit 1 if stale")
    args = parser.parse_args(argv)
    target = args.root / "docs" / "reproductions.md"
    try:
        text = generate(args.root / "docs" / "claims", args.root)
    except ClaimError as error:
        print(f"reproductions: error: {error}", file=sys.stderr)
        return 2
    if args.check:
        stale = not target.is_file() or target.read_text(encoding="utf-8") != text
        print(f"reproductions: {target} is {'stale' if stale else 'up to date'}")
        return int(stale)
    target.write_text(text, encoding="utf-8")
    print(f"reproductions: wrote {target}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
