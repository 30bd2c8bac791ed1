"""The ledger of reproduced claims, ``docs/reproductions.md`` and its twin ``docs/reproductions.csv``,
generated from the checked-in results.

Every claim of a seed or a published table that quadest reproduces is one entry of a claim file
``docs/claims/<source>.yaml``: what the source says (its own printed value, typed from the source),
the command that made our result, and *how to read* our number from a checked-in CSV (``measure``:
``file``, ``select``, ``value``, ``ci``, ``scale``, ``unit``, and optionally ``runs``, the column of
the run count, and ``p`` with ``test``, the column of a raw two-sided test p and the test that gave
it; or ``published``, for a source's Monte Carlo mean: :func:`published_interval`). Our numbers
are never typed: they are read here, from ``results/``, with their 95 % confidence interval, and
the verdict follows from the interval and the claim's rule (``expect``), five-way as
:mod:`quadest.aggregate.verdicts` defines it: reproduced, contradicted, inconclusive, not comparable,
not testable.

A claim whose verdict turns on a reconstruction choice the source does not fix names the choice
(``choice``) and gives one entry per reading under ``readings`` (each with ``reading``, ``command``,
``measure`` and optionally its own ``expect``; a reading we have not run gives ``why`` instead of a
measure). Readings that disagree make the claim *not comparable*; readings that agree give their
common verdict; a reading not run leaves the claim *inconclusive*, with the ``why`` saying what
would decide it. A claim marked ``testable: false`` gives ``why`` and is *not testable*. Every
verdict other than *reproduced* needs a ``cause`` (a claim file without one is an error). A claim
that our results could decide but no checked-in run does gives ``needs`` (the run that would decide
it) instead of a measure, and is *inconclusive*.

The tests of the claims of one source in one job (one results file, one sweep cell) are one family:
their raw p are Holm-corrected over that family here, and a test that cannot pass at its run count
is refused with an error naming the claim.

``python -m quadest.aggregate.reproductions`` (from the repository root) rewrites both files;
``--check`` only compares and exits 1 when either is stale. ``tests/test_reproductions.py`` runs the
check, so a regenerated result that changes a verdict without the ledger following fails the suite.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
import yaml
from scipy import stats

from quadest.aggregate import verdicts as v
from quadest.aggregate.reproduction_entries import Entry, Outcome, Reading, Sequential
from quadest.aggregate.reproductions_render import render_csv, render_markdown

CLAIM_KEYS = {"claim", "where", "source_value", "command", "measure", "expect", "cause", "testable", "why",
              "choice", "readings", "needs"}  # fmt: skip
READING_KEYS = {"reading", "command", "measure", "expect", "why"}
MEASURE_KEYS = {"file", "select", "value", "ci", "scale", "unit", "p", "test", "runs", "sequential", "published"}
PUBLISHED_KEYS = {"std", "runs", "rounding", "confidence"}
"""``measure.published``: our Monte Carlo mean against a published one (:func:`published_interval`)."""
SEQUENTIAL_COLUMNS = {"value": "estimate", "ci": ["ci_low", "ci_high"], "runs": "runs", "unit": "%"}
"""What ``sequential: true`` reads from a ``runs=auto`` job's ``decisions.csv`` (the estimate and its
α-spending interval are already in % of the reference)."""
PAIR_COLUMNS = {"pair", "estimator", "reference", "state", "arm", "metric", "step"}
"""Select columns that name a comparison inside a job; the others (a sweep cell) name the job."""


class ClaimError(ValueError):
    """A claim file that cannot be read into the ledger (the message names the file and the claim)."""


def read_measure(measure: dict, root: Path, label: str) -> Reading:
    """Read ``measure`` from the CSV under ``root``; a negative ``scale`` swaps the CI's ends so it stays ordered."""
    unknown = set(measure) - MEASURE_KEYS
    if unknown:
        raise ClaimError(f"{label}: unknown measure key(s) {sorted(unknown)}; allowed: {sorted(MEASURE_KEYS)}")
    if measure.get("sequential"):
        measure = _sequential_measure(measure, label)
    if "published" in measure and ("ci" in measure or "runs" not in measure):
        raise ClaimError(f"{label}: measure.published makes the interval from measure.runs; drop measure.ci")
    for key in ("file", "value"):
        if key not in measure:
            raise ClaimError(f"{label}: measure.{key} is required")
    if ("p" in measure) != ("test" in measure) or ("p" in measure and "runs" not in measure):
        raise ClaimError(f"{label}: measure.p needs measure.test (one of {list(v.TESTS)}) and measure.runs")
    path = root / measure["file"]
    if not path.is_file():
        raise ClaimError(f"{label}: measure.file {measure['file']} does not exist")
    table = pd.read_csv(path)
    rows = table
    select = measure.get("select") or {}
    for column, wanted in select.items():
        if column not in table.columns:
            raise ClaimError(f"{label}: select column {column!r} is not in {measure['file']}")
        rows = rows[rows[column].astype(str) == str(wanted)]
    if len(rows) != 1:
        raise ClaimError(f"{label}: select {measure.get('select')} matches {len(rows)} rows of {measure['file']}")
    row = rows.iloc[0]
    scale = float(measure.get("scale", 1.0))
    columns = [measure["value"], *(measure.get("ci") or [measure["value"]] * 2)]
    extra = [measure[k] for k in ("p", "runs") if k in measure]
    missing = [c for c in [*columns, *extra] if c not in table.columns]
    if missing:
        raise ClaimError(f"{label}: column(s) {missing} are not in {measure['file']}")
    value, low, high = (float(row[c]) * scale for c in columns)
    interval = ""
    if "published" in measure:
        published = measure["published"]
        low, high = published_interval(value, row, published, int(row[measure["runs"]]), scale, label)
        interval = (f"where the source's {int(published['runs'])}-run mean should fall, "
                    f"{100 * float(published.get('confidence', 0.95)):g} %")  # fmt: skip
    if scale < 0:
        low, high = high, low
    runs = int(row[measure["runs"]]) if "runs" in measure else None
    family = (measure["file"], *sorted((k, str(w)) for k, w in select.items() if k not in PAIR_COLUMNS))
    p_raw = float(row[measure["p"]]) if "p" in measure else None
    sequential = _sequential(row, path, label) if measure.get("sequential") else None
    comparison = tuple(sorted((k, str(w)) for k, w in select.items()))
    return Reading(value, low, high, str(measure.get("unit", "")), p_raw, measure.get("test"), runs, family, sequential,
                   comparison, interval)  # fmt: skip


def published_interval(value: float, row: pd.Series, published: dict, runs: int, scale: float,
                       label: str) -> tuple[float, float]:  # fmt: skip
    """Where a published Monte Carlo mean of the same quantity should fall, given ours: ``value ±
    (t · s · √(1/N + 1/N_pub) + rounding)``. Both means are averages of independent per-run values, so
    their difference has standard error ``s √(1/N + 1/N_pub)``, with ``s`` our per-run standard
    deviation (``published.std``, a column) standing in for the source's, which it rarely prints;
    ``published.runs`` is the source's run count and ``published.rounding`` half a unit of its last
    printed digit. ``published.confidence`` (default 0.95) is the claim file's to lower for a table
    of several rows compared at once (Bonferroni: ``1 − 0.05/rows``). The rule ``contains`` then asks
    whether the printed value lies in this interval."""
    unknown = set(published) - PUBLISHED_KEYS
    if unknown or not {"std", "runs"} <= set(published):
        raise ClaimError(f"{label}: measure.published needs std and runs (optional rounding, confidence); "
                         f"unknown {sorted(unknown)}")  # fmt: skip
    if published["std"] not in row.index:
        raise ClaimError(f"{label}: measure.published.std column {published['std']!r} is not in the file")
    confidence = float(published.get("confidence", 0.95))
    n, n_pub = runs, int(published["runs"])
    if not (0.0 < confidence < 1.0 and n >= 2 and n_pub >= 1):
        raise ClaimError(f"{label}: measure.published needs 0 < confidence < 1, our runs >= 2, the source's >= 1")
    spread = float(row[published["std"]]) * abs(scale)
    half = stats.t.isf((1.0 - confidence) / 2.0, n - 1) * spread * np.sqrt(1.0 / n + 1.0 / n_pub)
    half += float(published.get("rounding", 0.0))
    return value - half, value + half


def _sequential_measure(measure: dict, label: str) -> dict:
    """``sequential: true``: the columns of ``decisions.csv``; a test p has no place (the interval is
    the α-spending one, its level fixed by the job)."""
    fixed = set(measure) & {"value", "ci", "runs", "unit", "scale", "p", "test"}
    if fixed:
        raise ClaimError(f"{label}: measure.sequential reads decisions.csv's own columns; drop {sorted(fixed)}")
    return {**measure, **SEQUENTIAL_COLUMNS}


def _sequential(row: pd.Series, path: Path, label: str) -> Sequential:
    """The comparison's verdict and margin from its ``decisions.csv`` row, the budget and level from
    the job's config beside it (``config.yaml``, or ``.hydra/config.yaml`` in a sweep cell)."""
    for column in ("verdict", "margin"):
        if column not in row.index:
            raise ClaimError(f"{label}: measure.sequential needs a decisions.csv (no column {column!r} in {path})")
    configs = [path.parent / "config.yaml", path.parent / ".hydra" / "config.yaml"]
    config = next((c for c in configs if c.is_file()), None)
    if config is None:
        raise ClaimError(f"{label}: measure.sequential needs the job's config.yaml beside {path.name}")
    job = yaml.safe_load(config.read_text(encoding="utf-8")) or {}
    rules = job.get("decision") or {}
    if job.get("runs") != "auto" or "alpha" not in rules or "max_runs" not in rules:
        raise ClaimError(f"{label}: {config} is not a runs=auto job's config (runs: auto, decision.alpha, max_runs)")
    return Sequential(str(row["verdict"]), float(row["margin"]), int(rules["max_runs"]), float(rules["alpha"]))


def _rule(expect: object, label: str) -> v.Rule:
    try:
        return v.Rule.parse(expect)
    except v.RuleError as error:
        raise ClaimError(f"{label}: {error}") from None


def _readings(claim: dict, label: str) -> list[dict]:
    """The claim's readings, each with its command, measure (or why) and expect."""
    if "readings" not in claim:
        for key in ("command", "measure", "expect"):
            if key not in claim:
                raise ClaimError(f"{label}: '{key}' is required (or testable: false with 'why')")
        return [{"reading": "", "command": claim["command"], "measure": claim["measure"], "expect": claim["expect"]}]
    if (
        not str(claim.get("choice", "")).strip()
        or not isinstance(claim["readings"], list)
        or len(claim["readings"]) < 2
    ):
        raise ClaimError(f"{label}: 'readings' needs a 'choice' and at least two readings")
    out = []
    for i, reading in enumerate(claim["readings"]):
        unknown = set(reading) - READING_KEYS
        if unknown:
            raise ClaimError(
                f"{label} reading {i + 1}: unknown key(s) {sorted(unknown)}; allowed: {sorted(READING_KEYS)}"
            )
        if not str(reading.get("reading", "")).strip() or ("measure" in reading) == ("why" in reading):
            raise ClaimError(f"{label} reading {i + 1}: needs 'reading' and either 'command' + 'measure' or 'why'")
        if "measure" in reading and "command" not in reading:
            raise ClaimError(f"{label} reading {i + 1}: 'command' is required with 'measure'")
        if "measure" in reading and "expect" not in reading and "expect" not in claim:
            raise ClaimError(f"{label} reading {i + 1}: 'expect' is required (here or on the claim)")
        out.append({"expect": claim.get("expect"), **reading})
    return out


@dataclass(frozen=True)
class _Pending:
    """A claim read but not yet decided (its tests' Holm correction needs the whole family)."""

    label: str
    claim: dict
    readings: list[tuple[dict, v.Rule | None, Reading | None]]


def _read_claim(claim: dict, root: Path, label: str) -> _Pending:
    unknown = set(claim) - CLAIM_KEYS
    if unknown:
        raise ClaimError(f"{label}: unknown key(s) {sorted(unknown)}; allowed: {sorted(CLAIM_KEYS)}")
    for key in ("claim", "where", "source_value"):
        if not str(claim.get(key, "")).strip():
            raise ClaimError(f"{label}: '{key}' is required")
    if claim.get("testable", True) is False:
        if not str(claim.get("why", "")).strip():
            raise ClaimError(f"{label}: a claim with testable: false needs 'why'")
        return _Pending(label, claim, [])
    if "needs" in claim:
        if not str(claim["needs"]).strip() or {"command", "measure", "readings"} & set(claim):
            raise ClaimError(f"{label}: 'needs' names the run that would decide the claim, without a measure")
        return _Pending(label, claim, [])
    readings = []
    for spec in _readings(claim, label):
        if "measure" not in spec:
            readings.append((spec, None, None))
            continue
        readings.append((spec, _rule(spec["expect"], label), read_measure(spec["measure"], root, label)))
    return _Pending(label, claim, readings)


def _families(pending: list[_Pending]) -> dict[tuple, list[tuple[str, Reading]]]:
    """The tested readings of one source, grouped by job (results file and sweep cell)."""
    families: dict[tuple, list[tuple[str, Reading]]] = {}
    for item in pending:
        for _, _, reading in item.readings:
            if reading is not None and reading.p_raw is not None:
                families.setdefault(reading.family, []).append((item.label, reading))
    return families


def _corrected(pending: list[_Pending]) -> dict[int, tuple[float, int]]:
    """Holm p and family size per tested reading (keyed by ``id`` of the reading); refuses a test
    that cannot pass at its run count."""
    out: dict[int, tuple[float, int]] = {}
    for members in _families(pending).values():
        size = len(members)
        floor = min(v.minimum_p(r.test, r.runs) for _, r in members)
        for label, reading in members:
            try:
                v.check_attainable(reading.test, reading.runs, floor, size)
            except v.RuleError as error:
                raise ClaimError(f"{label}: {error}") from None
        for (_, reading), p in zip(members, v.holm_over_claims([r.p_raw for _, r in members]), strict=True):
            out[id(reading)] = (p, size)
    return out


def _check_sequential_levels(pending: list[_Pending]) -> None:
    """The comparisons that one source's claims read from one ``decisions.csv`` are one family, as a
    job's tests are: their α-spending intervals, each at the job's ``decision.alpha``, hold together at
    level 0.05 only when ``alpha`` × (comparisons) ≤ 0.05 (Bonferroni; two claims reading one
    comparison count once); a job run at a larger ``alpha`` is refused."""
    families: dict[tuple, dict[tuple, tuple[str, Reading]]] = {}
    for item in pending:
        for _, _, reading in item.readings:
            if reading is not None and reading.sequential is not None:
                families.setdefault(reading.family, {}).setdefault(reading.comparison, (item.label, reading))
    for members in families.values():
        label, first = next(iter(members.values()))
        alpha, size = first.sequential.alpha, len(members)
        if alpha * size > v.SIGNIFICANCE * (1 + 1e-9):
            raise ClaimError(
                f"{label}: {size} comparisons are read from {first.family[0]} at decision.alpha={alpha:g}; "
                f"together they need decision.alpha <= {v.SIGNIFICANCE}/{size} (Bonferroni)"
            )


def _decide(item: _Pending, corrected: dict[int, tuple[float, int]], source: str) -> Entry:
    claim = item.claim
    base = dict(source=source, claim=claim["claim"], where=claim["where"], source_value=str(claim["source_value"]),
                choice=str(claim.get("choice", "")).strip())  # fmt: skip
    if "needs" in claim:
        return Entry(**base, outcomes=(), verdict=v.INCONCLUSIVE, cause=" ".join(str(claim["needs"]).split()))
    if not item.readings:
        return Entry(**base, outcomes=(), verdict=v.NOT_TESTABLE, cause=" ".join(str(claim["why"]).split()))
    outcomes = []
    for spec, rule, reading in item.readings:
        if reading is None:
            outcome = Outcome(spec["reading"], "-", None, None, v.Decision(v.INCONCLUSIVE), why=str(spec["why"]))
        else:
            p, size = corrected.get(id(reading), (None, 1))
            decision = v.decide(reading.value, reading.low, reading.high, rule, p=p, p_raw=reading.p_raw,
                                family=size, runs=reading.runs)  # fmt: skip
            if reading.sequential is not None:
                decision = v.with_sequential(decision, reading.sequential.verdict, reading.sequential.margin,
                                             reading.sequential.max_runs)  # fmt: skip
            outcome = Outcome(spec["reading"], spec["command"], rule, reading, decision, p, size)
        outcomes.append(outcome)
    run = {o.decision.verdict for o in outcomes if o.reading is not None}
    if len(run) > 1:
        verdict = v.NOT_COMPARABLE
    elif any(o.reading is None for o in outcomes):
        verdict = v.INCONCLUSIVE
    else:
        verdict = run.pop()
    cause = " ".join(str(claim.get("cause", "")).split())
    if verdict != v.REPRODUCED and not cause:
        raise ClaimError(f"{item.label}: {verdict}, so 'cause' is required")
    return Entry(**base, outcomes=tuple(outcomes), verdict=verdict, cause=cause)


def build_entries(claims: list[dict], root: Path, source: str, label: str = "claim") -> list[Entry]:
    """The ledger rows of one source's claims (Holm runs over their tests, job by job)."""
    pending = [_read_claim(claim, root, f"{label} {i + 1}") for i, claim in enumerate(claims)]
    corrected = _corrected(pending)
    _check_sequential_levels(pending)
    return [_decide(item, corrected, source) for item in pending]


def build_entry(claim: dict, root: Path, label: str) -> Entry:
    """One claim alone (a family of one), as :func:`build_entries` would decide it."""
    return build_entries([claim], root, "test", label)[0]


def read_claim_file(path: Path, root: Path) -> tuple[str, list[Entry]]:
    """The title and the entries of one ``docs/claims/<source>.yaml``."""
    spec = yaml.safe_load(path.read_text(encoding="utf-8")) or {}
    if not spec.get("title") or not spec.get("claims"):
        raise ClaimError(f"{path.name}: needs 'title' and a non-empty 'claims' list")
    return spec["title"], build_entries(spec["claims"], root, spec.get("source", path.stem), f"{path.name} claim")


def generate(claims_dir: Path, root: Path) -> tuple[str, str]:
    """The ledger (Markdown, CSV) from every ``*.yaml`` in ``claims_dir`` (sorted by file name) and the
    results under ``root``."""
    files = sorted(claims_dir.glob("*.yaml"))
    if not files:
        raise ClaimError(f"no claim files in {claims_dir}")
    sections = [read_claim_file(path, root) for path in files]
    return render_markdown(sections), render_csv(sections)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m quadest.aggregate.reproductions", description=__doc__.split("\n")[0]
    )
    parser.add_argument("--root", type=Path, default=Path("."), help="the repository root (default: .)")
    parser.add_argument("--check", action="store_true", help="only compare with the ledger on disk; exit 1 if stale")
    args = parser.parse_args(argv)
    targets = (args.root / "docs" / "reproductions.md", args.root / "docs" / "reproductions.csv")
    try:
        texts = generate(args.root / "docs" / "claims", args.root)
    except ClaimError as error:
        print(f"reproductions: error: {error}", file=sys.stderr)
        return 2
    if args.check:
        stale = [t for t, text in zip(targets, texts, strict=True)
                 if not t.is_file() or t.read_text(encoding="utf-8") != text]  # fmt: skip
        print(f"reproductions: {', '.join(map(str, stale)) or 'the ledger'} {'stale' if stale else 'up to date'}")
        return int(bool(stale))
    for target, text in zip(targets, texts, strict=True):
        target.write_text(text, encoding="utf-8")
        print(f"reproductions: wrote {target}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
