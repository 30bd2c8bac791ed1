"""One way to run an experiment: ``quadest experiment=NAME`` runs every checked-in experiment, the
single jobs and the sweeps with their launcher, grid and callbacks (docs/experiments.md, "Running
an experiment"). ``quadest -cd experiments -cn NAME`` is only what it turns into for a file of
``experiments/``, and no page teaches it as a second way. Compose-level: nothing here runs a job."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir
from hydra.core.global_hydra import GlobalHydra
from hydra.types import RunMode
from omegaconf import DictConfig, OmegaConf

from quadest.app import cli
from quadest.app.schema import register_schemas
from quadest.config.paths import config_dir

ROOT = Path(__file__).resolve().parents[1]
EXPERIMENTS = ROOT / "experiments"
GROUP = Path(config_dir()) / "experiment"
FILES = sorted(p.stem for p in EXPERIMENTS.glob("*.yaml"))
GROUP_NAMES = sorted(p.stem for p in GROUP.glob("*.yaml"))


def compose_argv(argv: list[str]) -> DictConfig:
    """The config, with its ``hydra`` node, that Hydra composes for ``quadest ARGV``: the primary
    config that ``--config-dir``/``-cd`` and ``--config-name``/``-cn`` name (a relative folder from
    the repository root), else the root config; a sweep on the command line at its first value."""
    folder, name, overrides = config_dir(), "config", []
    args = list(argv)
    while args:
        arg = args.pop(0)
        if arg in ("--config-dir", "-cd"):
            folder = str(ROOT / args.pop(0))  # an absolute path stays itself
        elif arg in ("--config-name", "-cn"):
            name = args.pop(0)
        else:
            overrides.append(arg)
    register_schemas()
    GlobalHydra.instance().clear()
    try:
        with initialize_config_dir(config_dir=folder, version_base="1.3"):
            return compose(config_name=name, overrides=cli._cells(overrides)[0], return_hydra_config=True)
    finally:
        GlobalHydra.instance().clear()


def declared_hydra(path: Path) -> DictConfig:
    """The ``hydra`` node an experiment file declares, merged over those of the experiments it
    builds on (``override /experiment: NAME`` in a file of ``experiments/``, a plain ``NAME`` in
    a group file's defaults), read from the YAML files themselves, not through ``cli``."""
    spec = OmegaConf.load(path)
    merged = OmegaConf.create({})
    for entry in spec.get("defaults", []):
        parent = entry.get("override /experiment") if isinstance(entry, DictConfig) else entry
        if isinstance(parent, str) and (GROUP / f"{parent}.yaml").is_file():
            merged = OmegaConf.merge(merged, declared_hydra(GROUP / f"{parent}.yaml"))
    return OmegaConf.merge(merged, spec.get("hydra", {}))


def test_an_experiment_name_is_in_one_folder_only():
    assert FILES and GROUP_NAMES
    assert not set(FILES) & set(GROUP_NAMES)


@pytest.mark.parametrize("name", FILES + GROUP_NAMES)
@pytest.mark.slow
def test_the_one_way_runs_every_experiment_as_its_file_declares(name):
    """``quadest experiment=NAME runs=2`` composes the experiment with the override, and a sweep
    stays a sweep: Hydra's mode, the grid (``hydra.sweeper.params``) and the end-of-sweep
    callbacks are the ones its file declares."""
    path = EXPERIMENTS / f"{name}.yaml" if name in FILES else GROUP / f"{name}.yaml"
    argv, primary = cli.one_way([f"experiment={name}", "runs=2"])
    assert primary == (path if name in FILES else None)
    cfg = compose_argv(argv)
    assert cfg.runs == 2
    declared = declared_hydra(path)
    sweep = declared.get("mode") == "MULTIRUN"
    assert (cfg.hydra.mode == RunMode.MULTIRUN) == sweep, name
    params = OmegaConf.select(declared, "sweeper.params", default=None)
    got = cfg.hydra.sweeper.get("params")
    assert (OmegaConf.to_container(got) if got else {}) == (OmegaConf.to_container(params) if params else {})
    assert set(declared.get("callbacks", {})) <= set(cfg.hydra.callbacks or {})
    if name in FILES:
        assert sweep, f"experiments/{name}.yaml is not a sweep (hydra.mode: MULTIRUN); make it a group option"


@pytest.mark.parametrize("name", FILES)
@pytest.mark.slow
def test_the_old_form_is_what_the_one_way_runs(name):
    """For a file of ``experiments/``, ``quadest experiment=NAME ...`` hands Hydra exactly
    ``--config-dir experiments --config-name NAME ...`` (the records of the checked-in results
    were made that way) and composes the same config as ``quadest -cd experiments -cn NAME ...``."""
    rest = ["runs=2", "hydra.sweep.dir=/tmp/somewhere"]
    argv, primary = cli.one_way(["-m", f"experiment={name}", *rest])
    assert argv == ["--config-dir", str(EXPERIMENTS), "--config-name", name, "-m", *rest]
    assert primary == EXPERIMENTS / f"{name}.yaml"
    one, old = compose_argv(argv[:4] + rest), compose_argv(["-cd", "experiments", "-cn", name, *rest])
    assert OmegaConf.to_container(one) == OmegaConf.to_container(old)


def test_other_arguments_pass_unchanged():
    for argv in (["runs=3"], ["experiment=ungm_pf", "runs=3"], ["-m", "experiment=ungm_pf,ungm_toolbox"], []):
        assert cli.one_way(argv) == (argv, None)


@pytest.mark.parametrize(
    ("argv", "words"),
    [
        (["experiment=nope"], ["experiment=nope", "allowed:", "sweep_ut_params", "ungm_pf"]),
        (["experiment=sweep_ut_params,ungm_pf"], ["experiment=sweep_ut_params,ungm_pf", "runs alone", "allowed"]),
        (["experiment=thesis_ch5", "-cn", "other"], ["experiment=thesis_ch5", "-cn"]),
    ],
)
def test_a_wrong_experiment_is_one_line(argv, words, capsys):
    with pytest.raises(SystemExit) as exc:
        cli.one_way(argv)
    assert exc.value.code == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("quadest: error: ")
    assert all(word in lines[0] for word in words), lines[0]


def test_the_one_way_checks_a_sweep_before_any_work(capsys):
    """Each value of a sweep given on the command line is checked (no ``-m`` needed in an
    experiment that sweeps); in a plain run a comma list stays Hydra's ambiguous-value error."""
    argv, primary = cli.one_way(["experiment=sweep_ut_params", "sweep.alpha=0.5,1.0", "runs=2"])
    cli.precheck(argv[4:], primary)  # passes
    argv, primary = cli.one_way(["experiment=sweep_ut_params", "sweep.alpha=0.5,-1.0"])
    with pytest.raises(SystemExit):
        cli.precheck(argv[4:], primary)
    assert "estimator.ukf.alpha=-1.0 is invalid" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        cli.precheck(["runs=1,2"])
    assert "Ambiguous value for argument 'runs=1,2'" in capsys.readouterr().err


def _section(text: str, heading: str) -> str:
    start = text.index(heading)
    end = text.find("\n## ", start + len(heading))
    return text[start : end if end >= 0 else None]


def test_the_experiments_page_documents_the_one_way_for_every_experiment():
    section = _section((ROOT / "docs" / "experiments.md").read_text(encoding="utf-8"), "## Running an experiment")
    assert "quadest experiment=NAME" in section
    missing = [name for name in FILES + GROUP_NAMES if f"`{name}`" not in section]
    assert not missing, f"docs/experiments.md, 'Running an experiment', does not list {missing}"
    for page in ("README.md", "docs/index.md", "docs/usage.md", "docs/cluster.md"):
        assert "experiments.md#running-an-experiment" in (ROOT / page).read_text(encoding="utf-8"), page


SECOND_WAY = re.compile(r"(-cd|--config-dir)[ =]+experiments\b")


def test_no_page_teaches_a_second_way():
    """``-cd experiments`` appears once on docs/experiments.md, where it is named as what the one
    way turns into, and on no other page (the ledger docs/reproductions.md, generated from
    docs/claims/, included)."""
    pages = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
    found = {p.relative_to(ROOT).as_posix(): len(SECOND_WAY.findall(p.read_text(encoding="utf-8"))) for p in pages}
    alias = [
        p for p in (ROOT / "docs" / "experiments.md").read_text(encoding="utf-8").split("\n\n") if SECOND_WAY.search(p)
    ]
    assert len(alias) == 1 and found["docs/experiments.md"] == 1
    assert "quadest experiment=NAME` turns into" in alias[0] and "not a second way" in alias[0]
    others = {page: n for page, n in found.items() if n and page != "docs/experiments.md"}
    assert not others, f"pages that show `quadest -cd experiments -cn NAME`; use `quadest experiment=NAME`: {others}"


def test_the_wheel_ships_the_sweep_files_beside_the_config_tree():
    """``experiment_files`` looks beside the config tree, so the wheel must place ``experiments/``
    where it places ``conf/`` (both under ``quadest/``); otherwise a sweep runs only from a clone."""
    import tomllib

    root = Path(__file__).resolve().parents[1]
    build = tomllib.loads((root / "pyproject.toml").read_text())["tool"]["hatch"]["build"]["targets"]
    shipped = build["wheel"]["force-include"]
    assert Path(shipped["experiments"]).parent == Path(shipped["conf"]).parent
    assert Path(shipped["experiments"]).name == cli.EXPERIMENTS and Path(shipped["conf"]).name == "conf"
    assert "experiments" in build["sdist"]["include"]
