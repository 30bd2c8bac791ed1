"""What a user's clone reads stands on its own: no project-issue numbers and no paths out of the
repository, in the sources, tests, configs, tools, benchmarks, examples and docs.

The rules, applied line by line to every text file under ``src/``, ``tests/``, ``conf/``,
``experiments/``, ``tools/``, ``benchmarks/``, ``examples/`` and ``docs/``, and to ``README.md``,
the hand-written ``README.md`` of ``results/`` and of each results folder, ``results/manifest.yaml``,
``mkdocs.yml`` and ``pyproject.toml`` (``__pycache__`` and binary files are skipped):

1. **No reference to one of this project's issues by number.** Flagged: the word ``issue`` or
   ``issues`` followed by a number, with or without ``#`` (any case), and a bare ``#`` followed by
   a number that starts a word (not an HTML entity, a URL fragment or a hex colour). Allowed: the
   same when the word right before it (possessive ``'s`` included) names an outside project in
   ``OUTSIDE_PROJECTS``, e.g. filterpy's tracker cited as "filterpy", then "issue", then its number.
   Such a line is a citation. A reference in words without a number ("a numba issue") is never
   flagged. Write what the issue meant instead: the capability, the reason or the target.
   The project name must stand on the same line as the number (lines are checked one by one).
2. **No path out of the repository.** Flagged: the parent directory's ``shared`` folder (two dots,
   a slash, ``shared``) and its reference-material folders (``shared``, a slash, then
   ``reference``, ``seeds`` or ``data``). A clone does not have them; bring what the docs need into
   ``docs/``. Other folders named ``shared`` (a cluster's scratch space) are allowed.

The rules are checked on examples first (``test_the_rules_flag_what_they_should``), so the scan
cannot pass because a pattern stopped matching.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
FOLDERS = ("src", "tests", "conf", "experiments", "tools", "benchmarks", "examples", "docs")
FILES = ("README.md", "results/manifest.yaml", "mkdocs.yml", "pyproject.toml")
WRITTEN_RESULTS = "results/**/README.md"  # the hand-written notes of the results folders (the rest is output)
SKIPPED_FOLDERS = {"__pycache__", ".pytest_cache", ".ruff_cache", ".hypothesis", "site"}

# Projects whose own issue trackers the code may cite by number ("<project> issue <number>").
OUTSIDE_PROJECTS = frozenset(
    {
        "filterpy",
        "numba",
        "numpy",
        "scipy",
        "hydra",
        "omegaconf",
        "pyulog",
        "px4",
        "mkdocs",
        "mkdocstrings",
        "pytest",
        "hypothesis",
        "ruff",
        "pandas",
        "matplotlib",
        "particles",
        "dynamax",
        "submitit",
        "optuna",
        "cpython",
        "python",
        "lapack",
        "openblas",
    }
)

ISSUE_REFERENCE = re.compile(
    r"(?:\b(?P<owner>[A-Za-z][\w.-]*?)(?:'s)?\s+)?"  # the word before, if any
    r"(?:\bissues?\s*#?|(?<![\w&/#:])#)"  # "issue", "issues", "issue #" or a bare "#"
    r"\d+\b",
    re.IGNORECASE,
)
OUTSIDE_PATH = re.compile(r"\.\./shared\b|\bshared/(?:reference|seeds|data)\b")


def problems_in(line: str) -> list[str]:
    """What the rules flag in one line (empty when it is clean)."""
    references = ISSUE_REFERENCE.finditer(line)
    found = [m.group(0) for m in references if (m.group("owner") or "").lower() not in OUTSIDE_PROJECTS]
    found += [m.group(0) for m in OUTSIDE_PATH.finditer(line)]
    return found


def checked_files() -> list[Path]:
    files = [ROOT / name for name in FILES if (ROOT / name).is_file()] + sorted(ROOT.glob(WRITTEN_RESULTS))
    for folder in FOLDERS:
        for path in sorted((ROOT / folder).rglob("*")):
            if path.is_file() and not SKIPPED_FOLDERS.intersection(path.relative_to(ROOT).parts):
                files.append(path)
    return files


def text_of(path: Path) -> str | None:
    """The file's text, or None for a binary file (a NUL byte, or not UTF-8)."""
    data = path.read_bytes()
    if b"\0" in data:
        return None
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        return None


# The flagged examples are assembled at run time so that this file passes its own scan.
PARENT = ".."
SHARED = "shared"
NUMBER = 14


@pytest.mark.parametrize(
    "line",
    [
        f"# the fix of issue {NUMBER}",
        f"Issue {NUMBER}'s target, met",
        f"the gaps of issue #{NUMBER} (each had no failing test)",
        f"see issues {NUMBER} and 15",
        f"(fixed in #{NUMBER})",
        f"the thesis text under {PARENT}/{SHARED}/reference/thesis.pdf",
        f"copied from {SHARED}/seeds/seed001.m",
    ],
)
def test_the_rules_flag_what_they_should(line):
    assert problems_in(line), line


@pytest.mark.parametrize(
    "line",
    [
        f"residual weights are wrong in filterpy issue #{NUMBER}",
        f"filterpy's issue {NUMBER}",
        f"a known Numba issue #{NUMBER}",
        "a numba issue with parallel loops (in words, no number)",
        "the issue: a rank-deficient Q",
        "color: #1f77b4; &#8212; https://example.org/page#3",
        "SWEEP=/shared/scratch/$USER/quadest/ut_1000",
        "the shared quadrotor",
    ],
)
def test_the_rules_allow_citations_and_ordinary_text(line):
    assert not problems_in(line), problems_in(line)


def test_no_issue_numbers_and_no_paths_out_of_the_repository():
    files = checked_files()
    assert ROOT / "src" / "quadest" / "__init__.py" in files and ROOT / "README.md" in files
    assert ROOT / "results" / "README.md" in files and ROOT / "results" / "ins_figure8" / "README.md" in files
    hits = []
    for path in files:
        text = text_of(path)
        if text is None:
            continue
        for number, line in enumerate(text.splitlines(), start=1):
            hits += [f"{path.relative_to(ROOT)}:{number}: {found!r}" for found in problems_in(line)]
    assert not hits, "project-issue numbers or paths out of the repository:\n" + "\n".join(hits)
