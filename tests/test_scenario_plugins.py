"""A scenario is one registration: the climb of docs/scenarios.md (``tests/plugins/climb_scenario.py``
and its YAML) registered from outside the package through the ``quadest.scenarios`` entry points,
its reference checked against the quintic it follows, its checks run before any work, and flown
end to end."""

from __future__ import annotations

import pandas as pd
import pytest

from plugin_site import PLUGINS, fake_site, fenced_blocks, quadest
from quadest.errors import ConfigError
from quadest.quadrotor import scenario_registry as registry
from quadest.quadrotor.scenarios import Hover

ENTRY_POINTS = "[quadest.scenarios]\nclimb = climb_scenario:Climb\n"


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    return fake_site(tmp_path_factory.mktemp("site"), ENTRY_POINTS)


@pytest.fixture
def climb(site, monkeypatch):
    """The climb registered in this process through its entry point; forgotten afterwards."""
    monkeypatch.syspath_prepend(str(site))
    monkeypatch.syspath_prepend(str(PLUGINS))
    registry.discover.cache_clear()
    yield registry.scenario_classes()["climb"]
    monkeypatch.undo()
    registry.discover.cache_clear()


def test_the_docs_walk_through_the_tested_files():
    blocks = [b.strip() for b in fenced_blocks("scenarios.md")]
    assert (PLUGINS / "climb_scenario.py").read_text().strip() in blocks
    assert (PLUGINS / "conf" / "scenario" / "climb.yaml").read_text().strip() in blocks


def test_the_climb_follows_its_quintic(climb):
    """Half-way through the climb the quintic 10s³ − 15s⁴ + 6s⁵ is at 1/2 with slope 30/16 per
    unit of s; before and after it the reference is the hover's, shifted by 0 and by ``height``."""
    scenario, hover = climb(height=2.0, climb_start=4.0, climb_time=3.0), Hover()
    middle = scenario.reference(5.5)
    assert middle.position[2] == pytest.approx(hover.reference(5.5).position[2] + 1.0, abs=1e-12)
    assert middle.velocity[2] == pytest.approx(2.0 * 30.0 / 16.0 / 3.0, abs=1e-12)
    assert scenario.reference(3.0).position[2] == hover.reference(3.0).position[2]
    assert scenario.reference(9.0).position[2] == pytest.approx(hover.reference(9.0).position[2] + 2.0, abs=1e-12)
    assert scenario.reference(9.0).velocity[2] == 0.0


@pytest.mark.parametrize("key", ["height", "climb_time", "altitude"])
def test_its_own_checks_name_the_key(climb, key):
    with pytest.raises(ConfigError) as refused:
        climb(**{key: 0.0}).validate()
    assert refused.value.key == f"scenario.{key}"


def test_a_bad_value_is_one_line_before_any_work(site, tmp_path):
    proc = quadest(["scenario=climb", "scenario.height=-1", f"hydra.run.dir={tmp_path / 'o'}"], tmp_path, site)
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == ["quadest: error: scenario.height=-1.0 is invalid: must be > 0"]


@pytest.mark.slow
def test_the_climb_is_flown_from_the_command_line(site, tmp_path):
    out = tmp_path / "run"
    args = ["scenario=climb", "estimator=[ekf]", "runs=2", "duration=8", "progress=false", "output.figures=false"]
    proc = quadest([*args, f"hydra.run.dir={out}"], tmp_path, site)
    assert proc.returncode == 0, proc.stderr
    table = pd.read_csv(out / "metrics.csv")
    assert set(table["estimator"]) == {"ekf"} and not table["diverged"].any()
