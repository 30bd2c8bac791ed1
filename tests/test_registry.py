"""One registry behaviour for every extension kind (:mod:`quadest.config.registry`): an
estimator, model or sensor of the repository that breaks its contract is one line naming it and
the reason, as a plugin's is; two extensions with one name are refused with one line naming both;
the view of the built-ins leaves installed plugins out; a registered extension whose YAML Hydra
cannot find is reported as such.

A module "of the repository" is a temporary file in a folder appended to the kind's package
path, so the scan finds it as it finds the package's own files; no broken module is added to
``src/``."""

from __future__ import annotations

import importlib
import sys
import textwrap

import pytest

import quadest.config.registry as generic
from plugin_site import PLUGINS, fake_site
from quadest.app import cli
from quadest.app.schema import register_schemas
from quadest.errors import PluginError
from quadest.estimators import registry as estimators
from quadest.quadrotor import scenario_registry as scenarios
from quadest.sensors import registry as sensors
from quadest.simulation import registry as models

REGISTRIES = {"estimator": estimators, "model": models, "scenario": scenarios, "sensor": sensors}

# A module of each kind's package that declares the extension "halfdone" and breaks the contract.
HALF_DONE = {
    "estimator": (
        "quadest.estimators",
        """
        from dataclasses import dataclass
        from quadest.estimators.base import Estimator

        @dataclass
        class HalfDoneParams:
            kind: str = "halfdone"

        class HalfDone(Estimator):
            config_name = "halfdone"
            Params = HalfDoneParams
        """,
        "HalfDone",
        "it does not implement covariance, initialize, mean, predict, update",
    ),
    "model": (
        "quadest.simulation",
        """
        from quadest.simulation.spec import ModelSpec

        HALF_DONE = ModelSpec("halfdone", schema=int, build=None, state_dimension=len)
        """,
        "HALF_DONE",
        "its schema must be a dataclass; its build must be callable",
    ),
    "scenario": (
        "quadest.quadrotor",
        """
        from quadest.quadrotor.scenarios import Scenario

        class HalfDone(Scenario):
            name = "halfdone"
        """,
        "HalfDone",
        "it must be a dataclass (its fields are the scenario node's keys)",
    ),
    "sensor": (
        "quadest.sensors",
        """
        from quadest.sensors.base import Sensor

        class HalfDone(Sensor):
            config_name = "halfdone"
        """,
        "HalfDone",
        "it does not implement measurement_model, simulate; its Settings must be a dataclass",
    ),
}

# A module declaring a usable extension named "twin", and the attribute that holds it ({x}: A, B).
TWIN = {
    "estimator": (
        "quadest.estimators",
        "from quadest.estimators.cubature import CKF\n\nclass Twin{x}(CKF):\n    config_name = 'twin'\n",
        "Twin{x}",
    ),
    "model": (
        "quadest.simulation",
        "import dataclasses\nfrom quadest.simulation.validation_data import LINEAR\n\n"
        "TWIN_{x} = dataclasses.replace(LINEAR, name='twin')\n",
        "TWIN_{x}",
    ),
    "scenario": (
        "quadest.quadrotor",
        "from dataclasses import dataclass\nfrom quadest.quadrotor.scenarios import Hover\n\n"
        "@dataclass\nclass Twin{x}(Hover):\n    name: str = 'twin'\n",
        "Twin{x}",
    ),
    "sensor": (
        "quadest.sensors",
        "from quadest.sensors.gps import Gps\n\nclass Twin{x}(Gps):\n    config_name = 'twin'\n",
        "Twin{x}",
    ),
}


@pytest.fixture
def fresh(monkeypatch):
    """Every registry scans again in the test and after it, and warns as a fresh process would."""
    monkeypatch.setattr(generic, "_warned", set())
    for registry in REGISTRIES.values():
        registry.discover.cache_clear()
    yield
    monkeypatch.undo()  # the test's packages and plugins gone before the registries scan again
    for registry in REGISTRIES.values():
        registry.discover.cache_clear()
    register_schemas()


@pytest.fixture
def in_repository(tmp_path, monkeypatch, fresh):
    """``add(package, module, text)``: a module of ``package`` as if it were a file of the
    repository (a folder appended to the package's path); forgotten afterwards."""
    added: list[str] = []

    def add(package: str, module: str, text: str) -> None:
        folder = tmp_path / package.replace(".", "_")
        folder.mkdir(exist_ok=True)
        (folder / f"{module}.py").write_text(textwrap.dedent(text))
        parent = importlib.import_module(package)
        if str(folder) not in parent.__path__:
            monkeypatch.setattr(parent, "__path__", [*parent.__path__, str(folder)])
        importlib.invalidate_caches()
        added.append(f"{package}.{module}")

    yield add
    for name in added:
        sys.modules.pop(name, None)


@pytest.fixture
def installed(tmp_path, monkeypatch, fresh):
    """``install(entry_points, name)``: a distribution ``name`` with ``entry_points`` (the text of
    its ``entry_points.txt``) installed in this process, with no YAML; forgotten afterwards."""
    site = tmp_path / "site"
    monkeypatch.syspath_prepend(str(PLUGINS))

    def install(entry_points: str, name: str = "fake-extensions") -> None:
        fake_site(site, entry_points, name=name, conf=None)
        monkeypatch.syspath_prepend(str(site))
        importlib.invalidate_caches()

    return install


def test_the_repository_extensions_all_meet_their_contracts():
    """No module of the package is refused: a break in one is a line here, not a silent skip."""
    for kind, registry in REGISTRIES.items():
        found = registry.discover()
        assert not [message for message in found.problems.values() if " plugin " not in message], kind
        assert found.builtins(), f"no built-in {kind}"


@pytest.mark.parametrize("kind", sorted(HALF_DONE))
def test_an_in_repository_contract_break_is_one_line_naming_it(kind, in_repository, capsys):
    package, text, attribute, reason = HALF_DONE[kind]
    in_repository(package, "halfdone", text)
    found = REGISTRIES[kind].discover()
    expected = f"{kind} {package}.halfdone.{attribute} does not meet the contract: {reason}"
    assert found.problems == {"halfdone": expected}
    assert "halfdone" not in found.usable and found.builtins()
    found.refuse_selected([], key=kind)
    assert capsys.readouterr().err == f"quadest: warning: {expected}\n"
    with pytest.raises(PluginError) as info:
        found.refuse_selected(["halfdone"], key=kind)
    assert str(info.value) == expected and info.value.key == kind


def test_a_broken_in_repository_estimator_is_named_when_its_yaml_is_selected(in_repository, capsys):
    """Its schema is stored as a placeholder, so the YAML composes and the pre-run check gives the
    registry's line, not Hydra's "could not load" with no options."""
    package, text, _, reason = HALF_DONE["estimator"]
    in_repository(package, "halfdone", text)
    register_schemas()
    with pytest.raises(SystemExit):
        cli.precheck(["estimator=[halfdone]", "+estimator.halfdone.kind=halfdone"])
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("quadest: error: estimator quadest.estimators.halfdone.HalfDone")
    assert reason in err[0]


@pytest.mark.parametrize("kind", sorted(TWIN))
def test_two_in_repository_extensions_with_one_name_are_an_error_naming_both(kind, in_repository):
    package, text, attribute = TWIN[kind]
    for x in "AB":
        in_repository(package, f"twin_{x.lower()}", text.format(x=x))
    found = REGISTRIES[kind].discover()
    a, b = (f"{package}.twin_{x.lower()}.{attribute.format(x=x)}" for x in "AB")
    assert found.problems == {"twin": f"two {kind}s are named 'twin': {a} and {b}; rename one"}
    assert "twin" not in found.usable
    with pytest.raises(PluginError, match=r"two .* named 'twin'"):
        found.refuse_selected(["twin"], key=kind)


def test_two_plugins_with_one_name_are_an_error_naming_both(installed):
    installed("[quadest.estimators]\nmy_iekf = my_iekf:MyIEKF\n", name="first-dist")
    installed("[quadest.estimators]\nmy_iekf = target_plugin:LinearizedKF\n", name="second-dist")
    found = estimators.discover()
    message = found.problems["my_iekf"]
    assert message.startswith("two estimator plugins are named 'my_iekf': entry point ")
    assert "'my_iekf = my_iekf:MyIEKF' of first-dist" in message
    assert "'my_iekf = target_plugin:LinearizedKF' of second-dist" in message
    assert "my_iekf" not in found.usable and "\n" not in message


def test_a_plugin_named_like_a_built_in_names_both(installed):
    installed("[quadest.estimators]\nckf = my_iekf:MyIEKF\n")
    found = estimators.discover()
    assert found.usable["ckf"].cls.__module__ == "quadest.estimators.cubature"  # the built-in stays
    assert found.problems["ckf"] == (
        "estimator plugin entry point 'ckf = my_iekf:MyIEKF' of fake-extensions collides with the built-in "
        "estimator 'ckf' (quadest.estimators.cubature.CKF); rename it"
    )


PLUGINS_OF_EACH_KIND = (
    "[quadest.estimators]\nmy_iekf = my_iekf:MyIEKF\n"
    "[quadest.models]\npendulum = pendulum_model:MODEL\n"
    "[quadest.scenarios]\nclimb = climb_scenario:Climb\n"
    "[quadest.sensors]\nrangefinder = rangefinder_sensor:Rangefinder\n"
)


def test_the_builtins_view_leaves_installed_plugins_out(installed):
    before = {kind: set(registry.discover().builtins()) for kind, registry in REGISTRIES.items()}
    installed(PLUGINS_OF_EACH_KIND)
    for registry in REGISTRIES.values():
        registry.discover.cache_clear()
    assert set(estimators.estimator_specs()) - set(estimators.builtin_estimators()) == {"my_iekf"}
    assert set(models.model_specs()) - set(models.builtin_model_specs()) == {"pendulum"}
    assert set(scenarios.scenario_classes()) - set(scenarios.builtin_scenario_classes()) == {"climb"}
    assert set(sensors.sensor_classes()) - set(sensors.builtin_sensor_classes()) == {"rangefinder"}
    assert {kind: set(registry.discover().builtins()) for kind, registry in REGISTRIES.items()} == before


# The tested plugins renamed "ghost": no YAML of theirs is on any search path, whatever search-path
# plugins other tests of the process have made Hydra load.
GHOSTS = """
import dataclasses

from climb_scenario import Climb
from my_iekf import MyIEKF
from pendulum_model import MODEL as PENDULUM
from rangefinder_sensor import Rangefinder

GHOST_MODEL = dataclasses.replace(PENDULUM, name="ghost")


class GhostFilter(MyIEKF):
    config_name = "ghost"


class GhostSensor(Rangefinder):
    config_name = "ghost"


@dataclasses.dataclass
class GhostScenario(Climb):
    name: str = "ghost"
"""
GHOST_ENTRY_POINTS = (
    "[quadest.estimators]\nghost = ghosts:GhostFilter\n"
    "[quadest.models]\nghost = ghosts:GHOST_MODEL\n"
    "[quadest.scenarios]\nghost = ghosts:GhostScenario\n"
    "[quadest.sensors]\nghost = ghosts:GhostSensor\n"
)


@pytest.mark.parametrize(
    ("override", "kind", "yaml"),
    [
        ("estimator=[ghost]", "estimator", "estimator/ghost.yaml"),
        ("model=ghost", "model", "model/ghost.yaml"),
        ("scenario=ghost", "scenario", "scenario/ghost.yaml"),
        ("+sensor/ghost=preset", "sensor", "sensor/ghost/preset.yaml"),
    ],
)
def test_a_registered_extension_without_its_yaml_is_reported_as_such(installed, tmp_path, capsys, override, kind, yaml):
    (tmp_path / "site").mkdir()
    (tmp_path / "site" / "ghosts.py").write_text(GHOSTS)
    installed(GHOST_ENTRY_POINTS)
    register_schemas()
    with pytest.raises(SystemExit):
        cli.precheck([override])
    err = capsys.readouterr().err.strip().splitlines()
    origin = REGISTRIES[kind].discover().origins["ghost"]
    assert err == [
        f"quadest: error: {kind} 'ghost' is registered ({origin}) but its YAML {yaml} is not on Hydra's config "
        "search path; an installed package ships it with a search-path plugin in its hydra_plugins/ folder "
        "(docs/plugins.md)"
    ]
    assert origin.endswith("of fake-extensions")
