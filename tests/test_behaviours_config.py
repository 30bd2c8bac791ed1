"""Configuration behaviours: a value that cannot run is refused before any work.

- A scenario's ``transition_time`` ≤ 0 (a step taken in no time: a division by zero in the smooth
  step) is one ``ConfigError`` naming ``scenario.transition_time``, for every scenario option of
  ``conf/scenario`` and every experiment of ``conf/experiment`` that has the key.
"""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from helpers import compose_config
from quadest.app.validate import validate
from quadest.errors import ConfigError

CONF = Path(__file__).resolve().parents[1] / "conf"


def with_transition_time() -> list[list[str]]:
    """The config selections whose scenario has a ``transition_time``."""
    out = []
    for path in sorted((CONF / "scenario").glob("*.yaml")):
        if "transition_time" in (yaml.safe_load(path.read_text()) or {}):
            out.append([f"scenario={path.stem}"])
    for path in sorted((CONF / "experiment").glob("*.yaml")):
        if "transition_time" in ((yaml.safe_load(path.read_text()) or {}).get("scenario") or {}):
            out.append([f"experiment={path.stem}"])
    return out


SELECTIONS = with_transition_time()


def test_the_property_has_members():
    assert len(SELECTIONS) >= 2


@pytest.mark.parametrize("selection", SELECTIONS, ids=lambda s: s[0])
def test_a_transition_time_that_is_not_positive_is_refused_before_any_work(selection):
    for value in (0.0, -0.5):
        with pytest.raises(ConfigError) as refused:
            validate(compose_config([*selection, "runs=2", "duration=1.0", f"scenario.transition_time={value}"]))
        assert refused.value.key == "scenario.transition_time"
        assert "\n" not in str(refused.value)
