"""Text formats shared by a job and the aggregation: Markdown and LaTeX tables, strict JSON."""

from __future__ import annotations

import json
import math

import numpy as np
import pandas as pd
import pytest

from quadest.aggregate.report import aggregate
from quadest.evaluation.formatting import latex_table, markdown_table, strict_json


def _strict_loads(text: str):
    """A parser that accepts only RFC 8259 JSON (Python's accepts NaN and Infinity by default)."""

    def reject(constant: str):
        raise ValueError(f"non-standard JSON constant {constant}")

    return json.loads(text, parse_constant=reject)


def test_strict_json_writes_null_for_every_non_finite_float():
    value = {"a": math.nan, "b": [1.5, math.inf, (-math.inf, 2)], "c": {"d": np.float64("nan"), "e": "nan"}}
    assert _strict_loads(strict_json(value)) == {"a": None, "b": [1.5, None, [None, 2]], "c": {"d": None, "e": "nan"}}
    assert strict_json({"x": 0.1}, indent=2) == json.dumps({"x": 0.1}, indent=2)


def test_strict_json_refuses_a_non_finite_key():
    """Keys are not values (``null`` is no key): ``allow_nan=False`` is the backstop."""
    with pytest.raises(ValueError, match="not JSON compliant"):
        strict_json({math.nan: 1})


def test_aggregate_report_quotes_a_non_finite_swept_value_as_null(tmp_path):
    (tmp_path / "multirun.yaml").write_text(
        "hydra:\n  sweeper:\n    params:\n      model.x: .nan\n      model.y: .inf\n"
    )
    report = aggregate(tmp_path).read_text()
    swept = next(line for line in report.splitlines() if line.startswith("- swept: "))
    assert _strict_loads(swept.removeprefix("- swept: ")) == {"model.x": None, "model.y": None}


def test_tables_by_hand():
    frame = pd.DataFrame({"state_x": ["1 ± 2", "-"], "n%": [3, 4.5]})
    assert markdown_table(frame) == "| state_x | n% |\n|---|---|\n| 1 ± 2 | 3.0 |\n| - | 4.5 |\n"
    assert latex_table(frame) == (
        "\\begin{tabular}{ll}\n\\hline\nstate\\_x & n\\% \\\\\n\\hline\n1 $\\pm$ 2 & 3.0 \\\\\n- & 4.5 \\\\\n"
        "\\hline\n\\end{tabular}\n"
    )


def test_a_missing_number_prints_n_a_in_markdown_as_in_the_console():
    frame = pd.DataFrame({"estimator": ["ekf", "pf"], "mean_nis": [2.5, np.nan]})
    lines = markdown_table(frame).splitlines()
    assert lines[2:] == ["| ekf | 2.5 |", "| pf | n/a |"]
