"""Numbers in the prose docs read from the checked-in results, as the ledger reads its own.

``docs/numbers.yaml`` maps a document (``docs/findings.md``, ``results/README.md``) to its quotes:
each quote is a piece of the document's text with ``{}`` where a number from ``results/`` stands,
and one ``numbers`` entry per ``{}`` says how to read it:

- ``file``, ``select`` (column → value, or a list of values), ``column``;
- ``reduce`` (``min``, ``max`` or ``mean``) when ``select`` matches several rows (else exactly one);
- ``scale`` (a factor, e.g. 100 for a percentage or −100 for "x % better") and ``format`` (a Python
  format spec such as ``.3g``).

``python -m quadest.aggregate.doc_numbers`` rewrites every quoted number in place (the text between
the quote's fixed parts, a number, is replaced); ``--check`` only compares and exits 1 when a document is
stale. A quote that does not occur exactly once, or a number that cannot be read, is an error that
names the document and the quote. ``tests/test_doc_numbers.py`` runs the check.
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

import pandas as pd
import yaml

NUMBER_KEYS = {"file", "select", "column", "reduce", "scale", "format"}
NUMBER = r"([−+-]?(?:\d[\d.,]*(?:e[−+-]?\d+)?|nan|inf))"
"""What stands for a ``{}`` in the document: a number as :func:`read_number` writes it."""
REDUCERS = {"min": min, "max": max, "mean": lambda xs: sum(xs) / len(xs)}


class NumberError(ValueError):
    """A quote or a number spec that cannot be resolved (the message names the document and the quote)."""


def read_number(spec: dict, root: Path, tables: dict[Path, pd.DataFrame]) -> str:
    """The formatted value of one ``numbers`` entry."""
    unknown = set(spec) - NUMBER_KEYS
    if unknown or not {"file", "column"} <= set(spec):
        raise NumberError(f"number keys must include file and column, from {sorted(NUMBER_KEYS)}; got {sorted(spec)}")
    path = root / spec["file"]
    if path not in tables:
        if not path.is_file():
            raise NumberError(f"{spec['file']} does not exist")
        tables[path] = pd.read_csv(path)
    rows = tables[path]
    for column, wanted in (spec.get("select") or {}).items():
        if column not in rows.columns:
            raise NumberError(f"select column {column!r} is not in {spec['file']}")
        allowed = [str(w) for w in (wanted if isinstance(wanted, list) else [wanted])]
        rows = rows[rows[column].astype(str).isin(allowed)]
    if spec["column"] not in rows.columns:
        raise NumberError(f"column {spec['column']!r} is not in {spec['file']}")
    values = [float(x) * float(spec.get("scale", 1.0)) for x in rows[spec["column"]]]
    reduce = spec.get("reduce")
    if reduce is None and len(values) != 1:
        raise NumberError(f"select {spec.get('select')} matches {len(values)} rows of {spec['file']} (no reduce)")
    if reduce is not None and (reduce not in REDUCERS or not values):
        raise NumberError(f"reduce must be one of {sorted(REDUCERS)} over at least one row, got {reduce!r}")
    value = values[0] if reduce is None else REDUCERS[reduce](values)
    return format(value, spec.get("format", ".3g")).replace("-", "−")


def rewrite(text: str, quotes: list[dict], root: Path, label: str) -> str:
    """``text`` with every quote's numbers replaced by the values read from ``root``."""
    tables: dict[Path, pd.DataFrame] = {}
    for quote in quotes:
        template, specs = quote["quote"], quote.get("numbers") or []
        parts = template.split("{}")
        if not parts[0] or not parts[-1]:
            raise NumberError(f"{label}: quote {template!r} must start and end with fixed text, not with {{}}")
        if len(parts) - 1 != len(specs):
            raise NumberError(f"{label}: quote {template!r} has {len(parts) - 1} {{}} but {len(specs)} numbers")
        pattern = re.compile(NUMBER.join(re.escape(p) for p in parts))
        matches = list(pattern.finditer(text))
        if len(matches) != 1:
            raise NumberError(f"{label}: quote {template!r} occurs {len(matches)} times (must be once)")
        try:
            values = [read_number(spec, root, tables) for spec in specs]
        except NumberError as error:
            raise NumberError(f"{label}: quote {template!r}: {error}") from None
        filled = "".join(p + v for p, v in zip(parts, [*values, ""], strict=True))
        match = matches[0]
        text = text[: match.start()] + filled + text[match.end() :]
    return text


def generate(root: Path) -> dict[Path, str]:
    """Every document of ``docs/numbers.yaml`` with its numbers read from the results under ``root``."""
    spec = yaml.safe_load((root / "docs" / "numbers.yaml").read_text(encoding="utf-8")) or {}
    out = {}
    for document, quotes in spec.items():
        path = root / document
        out[path] = rewrite(path.read_text(encoding="utf-8"), quotes, root, document)
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m quadest.aggregate.doc_numbers", description=__doc__.split("\n")[0])
    parser.add_argument("--root", type=Path, default=Path("."), help="the repository root (default: .)")
    parser.add_argument("--check", action="store_true", help="only compare with the documents; exit 1 if stale")
    args = parser.parse_args(argv)
    try:
        documents = generate(args.root)
    except NumberError as error:
        print(f"doc_numbers: error: {error}", file=sys.stderr)
        return 2
    stale = [path for path, text in documents.items() if path.read_text(encoding="utf-8") != text]
    if args.check:
        print(f"doc_numbers: {', '.join(map(str, stale)) or 'every document'} {'stale' if stale else 'up to date'}")
        return int(bool(stale))
    for path in stale:
        path.write_text(documents[path], encoding="utf-8")
        print(f"doc_numbers: wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
