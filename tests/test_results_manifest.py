"""results/manifest.yaml lists every checked-in results folder with the commands that make it, and
results/ keeps to its size budget."""

from __future__ import annotations

import importlib.util
import re
import shlex
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
BUDGET_BYTES = 34_000_000  # results/README.md: at most 34 MB (10^6 bytes) in git, raised for the ledger's evidence


def load_tool():
    spec = importlib.util.spec_from_file_location("regenerate_results", ROOT / "tools" / "regenerate_results.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def tracked_results() -> list[Path]:
    out = subprocess.run(["git", "ls-files", "results"], cwd=ROOT, capture_output=True, text=True, check=True)
    return [ROOT / line for line in out.stdout.splitlines()]


def test_manifest_names_exactly_the_checked_in_folders():
    manifest = load_tool().read_manifest()
    folders = {
        path.relative_to(ROOT / "results").parts[0] for path in tracked_results() if path.parent != ROOT / "results"
    }
    assert set(manifest) == folders


def test_every_manifest_command_writes_into_its_own_folder():
    """A command that wrote elsewhere would leave its folder stale after a regeneration; one that
    writes into a sub-folder of its own (a variant beside the main run) stays inside it."""
    for name, commands in load_tool().read_manifest().items():
        for command in commands:
            argv = shlex.split(command)
            assert argv[0] in {"quadest", "python"}, command
            assert any(re.search(rf"(^|[=/])results/{name}(/[\w.-]+)*$", arg) for arg in argv), command


def test_every_folder_is_described_in_results_readme():
    readme = (ROOT / "results" / "README.md").read_text(encoding="utf-8")
    for name in load_tool().read_manifest():
        assert f"`{name}/`" in readme, name


def test_results_keep_to_their_size_budget():
    size = sum(path.stat().st_size for path in tracked_results() if path.is_file())
    assert size <= BUDGET_BYTES, f"results/ holds {size / 1e6:.2f} MB in git; the budget is {BUDGET_BYTES / 1e6:g} MB"


def test_list_runs_nothing(capsys):
    assert load_tool().main(["--list", "--only", "ungm_pf"]) == 0
    assert "quadest experiment=ungm_pf" in capsys.readouterr().out


def test_unknown_folder_is_refused(capsys):
    assert load_tool().main(["--only", "no_such_folder"]) == 2
    assert "allowed" in capsys.readouterr().err


def _compose_command(command: str):
    """The task config a manifest command would run: its config (the experiment file that
    ``quadest experiment=NAME`` makes the primary config, ``-cd``/``-cn``, or the root config) with
    its overrides, less the Hydra settings and the multirun flag; a swept override takes its first
    value (the first job of the multirun)."""
    from hydra import compose, initialize_config_dir
    from hydra.core.global_hydra import GlobalHydra
    from hydra.core.override_parser.overrides_parser import OverridesParser

    from quadest.app.cli import one_way
    from quadest.app.schema import register_schemas
    from quadest.config.paths import config_dir

    argv = one_way(shlex.split(command)[1:])[0]
    folder, name, overrides = config_dir(), "config", []
    while argv:
        arg = argv.pop(0)
        if arg in ("-cd", "--config-dir"):
            folder = str(ROOT / argv.pop(0))  # an absolute path stays itself
        elif arg in ("-cn", "--config-name"):
            name = argv.pop(0)
        elif arg != "-m" and not arg.startswith("hydra."):
            parsed = OverridesParser.create().parse_override(arg)
            first = next(parsed.sweep_string_iterator()) if parsed.is_sweep_override() else None
            overrides.append(arg if first is None else f"{parsed.key_or_group}={first}")
    register_schemas()
    GlobalHydra.instance().clear()
    with initialize_config_dir(config_dir=folder, version_base="1.3"):
        cfg = compose(config_name=name, overrides=overrides)
    GlobalHydra.instance().clear()
    return cfg


@pytest.mark.slow
def test_every_manifest_command_composes_and_validates():
    """A regeneration must not stop on a config name or key that no longer exists: each command
    composes and passes the same validation the CLI runs before any work."""
    from quadest.app.validate import validate

    for commands in load_tool().read_manifest().values():
        for command in commands:
            if command.startswith("quadest "):
                validate(_compose_command(command))


def test_every_manifest_command_runs_its_experiment_the_one_way():
    """An experiment is run as ``quadest experiment=NAME`` (docs/experiments.md, "Running an
    experiment"), never through Hydra's ``-cd``/``-cn``, which that command turns into for a sweep
    file (tests/test_experiment_command.py)."""
    for commands in load_tool().read_manifest().values():
        for command in commands:
            argv = shlex.split(command)
            assert not {"-cd", "--config-dir", "-cn", "--config-name"} & set(argv), command


def test_regeneration_keeps_the_folder_readme_no_command_makes(tmp_path, monkeypatch):
    """A folder's hand-written README.md survives its regeneration; every other old file goes."""
    tool = load_tool()
    folder = tmp_path / "results" / "demo"
    (folder / "sub").mkdir(parents=True)
    (folder / "README.md").write_text("what this folder is")
    (folder / "sub" / "README.md").write_text("and this one")
    (folder / "stale.csv").write_text("old")
    monkeypatch.setattr(tool, "ROOT", tmp_path)

    def fake_run(command: str, env: dict[str, str] | None = None) -> bool:
        folder.mkdir(parents=True)
        (folder / "fresh.csv").write_text("new")
        return True

    monkeypatch.setattr(tool, "run", fake_run)
    assert tool.regenerate("demo", ["quadest whatever"])
    assert sorted(p.relative_to(folder).as_posix() for p in folder.rglob("*") if p.is_file()) == [
        "README.md", "fresh.csv", "sub/README.md",
    ]  # fmt: skip
