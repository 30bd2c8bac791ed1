"""Every test file is in one layer of the suite (docs/testing.md, "Layers"): a file missing from
``LAYERS`` in tests/conftest.py would run in no layer's command, only in the whole suite."""

from __future__ import annotations

from pathlib import Path

from conftest import LAYER_MARKERS, LAYERS

TESTS = Path(__file__).parent


def test_every_test_file_has_a_layer():
    missing = sorted(path.name for path in TESTS.glob("test_*.py") if path.name not in LAYERS)
    assert not missing, (
        f"{', '.join(missing)} in no layer: add a row to LAYERS in tests/conftest.py "
        f'(one of {", ".join(LAYER_MARKERS)}; docs/testing.md, "Layers")'
    )


def test_every_row_names_a_test_file_and_a_layer():
    stale = sorted(name for name in LAYERS if not (TESTS / name).is_file())
    assert not stale, f"LAYERS in tests/conftest.py names {', '.join(stale)}, which tests/ does not hold"
    unknown = {name: layer for name, layer in LAYERS.items() if layer not in LAYER_MARKERS}
    assert not unknown, f"LAYERS in tests/conftest.py: {unknown} is not one of {', '.join(LAYER_MARKERS)}"


def test_every_collected_test_carries_one_layer(request):
    """Of the tests this run collected (all of them in a full run), each carries exactly one layer
    marker: its file's from ``LAYERS`` or its own."""
    wrong = {
        item.nodeid: layers
        for item in request.session.items
        if len(layers := {mark.name for mark in item.iter_markers() if mark.name in LAYER_MARKERS}) != 1
    }
    assert not wrong, f"tests without exactly one layer: {dict(list(wrong.items())[:5])}"
