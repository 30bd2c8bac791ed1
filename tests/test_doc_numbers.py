"""Numbers in docs/findings.md and results/README.md are the checked-in results' (docs/numbers.yaml):
a result regenerated, or a number typed by hand, without the document following fails here."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest

from quadest.aggregate import doc_numbers

ROOT = Path(__file__).resolve().parents[1]


def test_the_docs_quote_the_checked_in_results():
    for path, text in doc_numbers.generate(ROOT).items():
        assert path.read_text(encoding="utf-8") == text, f"{path} is stale: python -m quadest.aggregate.doc_numbers"


@pytest.fixture()
def root(tmp_path: Path) -> Path:
    (tmp_path / "results").mkdir()
    pd.DataFrame({"estimator": ["a", "b", "c"], "rmse": [0.25, 0.5, 1.0], "rel": [-0.044, 0.1, 0.3]}).to_csv(
        tmp_path / "results" / "t.csv", index=False
    )
    return tmp_path


def number(**extra) -> dict:
    return {"file": "results/t.csv", "column": "rmse", **extra}


def test_a_stale_number_is_replaced_and_the_rest_kept(root: Path):
    """a's RMSE is 0.25; the document says 0.3: the number is rewritten, the text around it kept."""
    quotes = [{"quote": "a reaches {} m here", "numbers": [number(select={"estimator": "a"}, format=".2f")]}]
    assert doc_numbers.rewrite("so a reaches 0.3 m here.\n", quotes, root, "d") == "so a reaches 0.25 m here.\n"


def test_ranges_scales_and_signs(root: Path):
    """min and max over a and b (0.25, 0.5); a gain of −4.4 % written as 4.4 with scale −100; a
    negative number with the typographic minus."""
    quotes = [
        {
            "quote": "from {} to {} m",
            "numbers": [number(select={"estimator": ["a", "b"]}, reduce=r, format=".2f") for r in ("min", "max")],
        },
        {"quote": "gains {} %", "numbers": [number(column="rel", select={"estimator": "a"}, scale=-100, format=".1f")]},
        {"quote": "moves {} %", "numbers": [number(column="rel", select={"estimator": "a"}, scale=100, format=".1f")]},
    ]
    text = "from 1 to 2 m; gains 7 %; moves 3 %"
    assert doc_numbers.rewrite(text, quotes, root, "d") == "from 0.25 to 0.50 m; gains 4.4 %; moves −4.4 %"


@pytest.mark.parametrize(
    ("text", "quote", "spec", "message"),
    [
        ("a is 1; a is 1;", "a is {};", number(select={"estimator": "a"}), "occurs 2 times"),
        ("nothing here", "a is {};", number(select={"estimator": "a"}), "occurs 0 times"),
        ("a is 1;", "a is {};", number(), "matches 3 rows"),
        ("a is 1;", "a is {};", number(select={"estimator": "a"}, column="nope"), "column 'nope'"),
        ("a is 1;", "a is {};", number(select={"estimator": "a"}, file="results/none.csv"), "does not exist"),
        ("a is 1", "a is {}", number(select={"estimator": "a"}), "must start and end with fixed text"),
    ],
)
def test_a_quote_that_cannot_be_resolved_is_refused(root: Path, text, quote, spec, message):
    with pytest.raises(doc_numbers.NumberError, match=message):
        doc_numbers.rewrite(text, [{"quote": quote, "numbers": [spec]}], root, "d")
