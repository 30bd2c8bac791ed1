"""``tools/mutations.py`` stays applicable: every mutation's text occurs exactly once in its file
and every test it names exists, so a refactor that moves the text makes this fail here rather than
stopping a long mutation run half-way (the full run is ``python tools/mutations.py``,
docs/testing.md)."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def load_tool():
    spec = importlib.util.spec_from_file_location("mutations", ROOT / "tools" / "mutations.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclasses look their module up while being defined
    spec.loader.exec_module(module)
    return module


TOOL = load_tool()


@pytest.mark.parametrize("mutation", TOOL.MUTATIONS, ids=lambda m: m.name)
def test_the_mutation_still_applies(mutation):
    assert TOOL.stale(mutation) is None


def test_a_moved_text_or_a_renamed_test_is_reported():
    first = TOOL.MUTATIONS[0]
    moved = TOOL.Mutation(first.name, first.file, first.old + "no longer here", first.new, first.tests)
    renamed = TOOL.Mutation(first.name, first.file, first.old, first.new, (first.tests[0] + "_renamed",))
    assert "occurs 0 times" in TOOL.stale(moved)
    assert "does not exist" in TOOL.stale(renamed)


def test_mutation_names_are_unique():
    names = [m.name for m in TOOL.MUTATIONS]
    assert len(names) == len(set(names))
