"""Text formats of the outputs: Markdown and LaTeX tables of a DataFrame, strict JSON.

Used by a job (``rmse_table.md``) and by the sweep aggregation (tables and report).
"""

from __future__ import annotations

import json
import math
import re

import pandas as pd


def markdown_table(frame: pd.DataFrame) -> str:
    """A GitHub-flavoured Markdown table of ``frame`` (no index); a missing number prints ``n/a``,
    as in the console's table."""
    cols = [str(c) for c in frame.columns]
    lines = ["| " + " | ".join(cols) + " |", "|" + "|".join("---" for _ in cols) + "|"]
    for row in frame.itertuples(index=False):
        lines.append("| " + " | ".join(_cell(v) for v in row) + " |")
    return "\n".join(lines) + "\n"


def _cell(value: object) -> str:
    if value is None:
        return ""
    return "n/a" if isinstance(value, float) and math.isnan(value) else str(value)


def latex_table(frame: pd.DataFrame) -> str:
    """A plain LaTeX ``tabular`` (no jinja2 needed)."""

    def esc(v) -> str:
        return re.sub(r"([_%&#$])", r"\\\1", str(v)).replace("±", r"$\pm$")

    lines = [
        r"\begin{tabular}{" + "l" * len(frame.columns) + "}",
        r"\hline",
        " & ".join(esc(c) for c in frame.columns) + r" \\",
        r"\hline",
    ]
    lines += [" & ".join(esc(v) for v in row) + r" \\" for row in frame.itertuples(index=False)]
    return "\n".join([*lines, r"\hline", r"\end{tabular}"]) + "\n"


def _finite_or_none(value):
    if isinstance(value, dict):
        return {k: _finite_or_none(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_finite_or_none(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def strict_json(value, **kwargs) -> str:
    """``json.dumps`` that writes strict JSON (RFC 8259): NaN and ±inf become ``null``, and
    ``allow_nan=False`` rejects any that would slip through."""
    return json.dumps(_finite_or_none(value), allow_nan=False, **kwargs)
