"""The ``quadest`` command: a Hydra app that runs one comparison per job.

``quadest`` runs the default comparison (EKF, UKF and SR-UKF on the thesis quadrotor) and prints
the per-state RMSE table, one line per estimator, one line per pair of estimators (the paired
comparison, ``docs/outputs.md``) and the output folder. Any key can be overridden
(``quadest estimator.srukf.alpha=0.1 sensor=tactical``) or swept (``quadest -m ...``). Data and
results computed before are loaded from the result cache (``docs/cache.md``).

``quadest experiment=NAME`` runs a checked-in experiment, a single job or a sweep alike
(``docs/experiments.md``): an option of the config group ``conf/experiment/`` is composed as any
group option; a sweep file ``experiments/NAME.yaml`` is a primary config of its own, and
:func:`one_way` hands it to Hydra as ``--config-dir experiments --config-name NAME``.
"""

from __future__ import annotations

import dataclasses
import math
import os
import re
import sys
import tempfile
from pathlib import Path

import hydra
from hydra import compose, initialize_config_dir
from hydra.core.global_hydra import GlobalHydra
from hydra.core.hydra_config import HydraConfig
from hydra.core.override_parser.overrides_parser import OverridesParser
from hydra.core.override_parser.types import ValueType
from hydra.types import RunMode
from omegaconf import DictConfig, OmegaConf, open_dict

from quadest.app.cell_record import failed_cells, record_cell
from quadest.app.job import run_validated
from quadest.app.parent_watch import watch_parent
from quadest.app.schema import register_schemas, registry_line
from quadest.app.validate import check_labels, validate
from quadest.config.paths import config_dir
from quadest.errors import ConfigError
from quadest.evaluation.formatting import strict_json
from quadest.evaluation.objective import objective_value

register_schemas()


@hydra.main(version_base="1.3", config_path=config_dir(), config_name="config")
def _main(cfg: DictConfig) -> float | None:
    """Run one job; with an ``objective`` configured, return it (what a tuning sweeper minimises;
    ``inf`` for a job that failed, so that the sweep goes on)."""
    hc = HydraConfig.get()
    out_dir = Path(hc.runtime.output_dir)
    multirun = hc.mode == RunMode.MULTIRUN
    failed = None if cfg.objective.estimator is None else math.inf
    watch_parent()  # a launcher's worker (joblib) dies with the sweep's main process
    try:
        check_labels(list(hc.overrides.task))
        settings = validate(cfg)  # the config, typed once (quadest.app.settings), objective included
        summary = run_validated(cfg, settings, out_dir, list(hc.overrides.task))
    except ConfigError as exc:
        if not multirun:
            _fail(str(exc))
        _record_failure(out_dir, f"ConfigError: {exc}")
        return failed
    except Exception as exc:  # in a sweep, one bad cell must not lose the others
        if not multirun:
            raise
        _record_failure(out_dir, f"{type(exc).__name__}: {exc}")
        return failed
    if multirun:
        record_cell("ok", out_dir)
    runs = summary.get("labels", {}).get("runs", cfg.runs)  # runs=auto: the runs it made
    print(f"\n{summary['_caption']}")  # quadest.evaluation.captions
    print(summary["_table"].to_string(index=False))
    if "_after_table" in summary:
        print(f"\n{summary['_after_table']}", end="")
    # NEES dof: the error state's (a closed-loop or replay summary has vector states, no error_names)
    n, m = len(summary.get("error_names", summary["state_names"])), len(summary["measurement_names"])
    for name, est in summary["estimators"].items():
        nis = (
            f"mean NIS {_fmt(est['mean_nis'])} ({m} dof, {_pct(est['nis_in_band'])} in band)"
            if m
            else "NIS per sensor " + ", ".join(f"{s} {_fmt(v)}" for s, v in est.get("nis_by_sensor", {}).items())
        )
        print(f"  {name:>8s}: {est['diverged']} of {runs} runs diverged{failure_note(est, runs)}, "
              f"mean NEES {_fmt(est['mean_nees'])} "
              f"({n} dof, {_pct(est['nees_in_band'])} of steps in the 95% band), {nis}, "
              f"{_fmt(est['step_time_us'], 1)} us/step/run"
              f"{' (from the cache)' if est['from_cache'] else ''}")  # fmt: skip
    if summary["_paired"]:
        print("\nPaired differences of per-run RMSE, estimator - reference, in % of the reference with the 95% "
              "Fieller CI\n(paired_comparison.csv; Holm over all pairs x states; runs diverged in either "
              "excluded):")  # fmt: skip
        for line in summary["_paired"]:
            print(f"  {line}")
    print(f"\nOutputs: {out_dir}")
    if cfg.objective.estimator is None:
        return None
    value = objective_value(settings.experiment.objective, summary)
    print(f"Objective ({cfg.objective.estimator}): {value:.6g}")
    return value


def _fmt(value: float | None, digits: int = 2) -> str:
    return "n/a" if value is None else f"{value:.{digits}f}"


def _pct(value: float | None) -> str:
    return "n/a" if value is None else f"{100 * value:.0f}%"


def failure_note(estimator: dict, runs: int) -> str:
    """Why an estimator's runs were flagged, for its summary line ('' when none was): the one reason
    of an estimator that could not run at all (an exception, a worker that died), else the first
    flagged run's, so that an error never reads as a plain divergence."""
    reasons = estimator.get("failure_reasons") or {}
    if not reasons:
        return ""
    first = min(reasons, key=int)
    if len(reasons) == runs and len(set(reasons.values())) == 1:
        return f" (every run: {reasons[first][:160]})"
    return f" (run {first}: {reasons[first][:160]})"


def _record_failure(out_dir: Path, reason: str) -> None:
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "summary.json").write_text(strict_json({"status": "failed", "error": reason}, indent=2))
    print(f"quadest: job failed: {reason}", file=sys.stderr)
    record_cell("failed", out_dir)


SWEEP_FAILED = 3
"""The exit status of a sweep in which any cell failed (its finished cells are kept)."""


def _exit_if_cells_failed() -> None:
    """After a sweep: exit with :data:`SWEEP_FAILED` and one line if any cell failed
    (:mod:`quadest.app.cell_record`, whichever launcher ran the cells)."""
    failed, cells = failed_cells()
    if failed:
        print(f"quadest: {len(failed)} of {cells} sweep cells failed (each one's summary.json says why): "
              f"{', '.join(failed)}", file=sys.stderr)  # fmt: skip
        sys.exit(SWEEP_FAILED)


_HYDRA_FLAGS = {
    "-m", "--multirun", "-h", "--help", "--hydra-help", "-i", "--info", "-c", "--cfg", "-sc",
    "--shell-completion", "--version", "-cd", "--config-dir", "-cn", "--config-name", "-cp",
    "--config-path", "--resolve", "-p", "--package", "--experimental-rerun",
}  # fmt: skip


def one_line(exc: BaseException) -> str:
    """Hydra's or OmegaConf's multi-line composition error as one line, with its cause; for a key
    that a schema does not have, the keys it does have; for an unknown group option, the options."""
    text = str(exc)
    cause = exc.__cause__ or exc.__context__
    if cause is not None and str(cause) not in text:
        text += "\n" + str(cause)
    keep = []
    for line in text.splitlines():
        text = line.strip()
        if text.startswith(("Config search path", "provider=", "object_type=", "Set the environment")):
            continue
        if text.startswith("full_key:"):
            text = f"(key {text.split(':', 1)[1].strip()})"
        if text:
            keep.append(text + ("," if line.startswith("\t") else ""))
    message = " ".join(keep).rstrip(",")
    missing = re.search(r"Could not (load|find) '([\w/]+)/([^']+)'", message)
    if missing:
        verb, group, name = missing.groups()
        line = registry_line(group, name)
        if line is not None:
            return line
        if verb == "load":  # after "Could not find" Hydra lists the options itself
            options = sorted(p.stem for p in (Path(config_dir()) / group).glob("*.yaml"))
            message += f" Available options in '{group}': {', '.join(options)}"
    schema = getattr(cause, "object_type", None) or getattr(exc, "object_type", None)
    if schema is not None and dataclasses.is_dataclass(schema) and "not in" in message:
        message += f"; allowed keys: {', '.join(f.name for f in dataclasses.fields(schema))}"
    return message


def precheck(argv: list[str], primary: Path | None = None) -> None:
    """Compose and validate a plain run's config before Hydra starts, so that a typo, a wrong
    type or a value out of range ends with one line and exit code 2, before any work. ``primary``
    is the experiment file that is the run's primary config (:func:`one_way`), else the root
    config. An experiment that sweeps (``hydra.mode: MULTIRUN``) takes sweeps on the command line
    without ``-m``: each of their values is checked (the other sweeps at their first value); in a
    single run a sweep is Hydra's "ambiguous value" error. With ``-m`` only the sweep's output
    folder is checked (:func:`check_sweep_dir`); the values are left to each job."""
    folder, name = (str(primary.parent), primary.stem) if primary is not None else (config_dir(), "config")
    hydra_args = [a for a in argv if a.lstrip("+~").startswith(("hydra.", "hydra/"))]
    flags = [arg for arg in argv if arg in _HYDRA_FLAGS or arg.startswith("--")]
    if flags and set(flags) <= {"-m", "--multirun"}:
        check_sweep_dir(folder, name, hydra_args)
    if flags:
        return
    overrides = [a for a in argv if a not in hydra_args]
    GlobalHydra.instance().clear()
    try:
        with initialize_config_dir(config_dir=folder, version_base="1.3"):
            for cell in _cells(overrides):
                cfg = compose(config_name=name, overrides=cell + hydra_args, return_hydra_config=True)
                sweeps = cfg.hydra.mode == RunMode.MULTIRUN
                if cell != overrides and not sweeps:
                    compose(config_name=name, overrides=overrides)  # raises Hydra's "ambiguous value"
                check_output_dir("hydra.sweep.dir" if sweeps else "hydra.run.dir", cfg)
                with open_dict(cfg):
                    del cfg["hydra"]
                check_labels(cell)
                validate(cfg)
    except ConfigError as exc:
        _fail(str(exc))
    except Exception as exc:  # Hydra/OmegaConf composition errors
        _fail(one_line(exc))
    finally:
        GlobalHydra.instance().clear()


_LISTED = (ValueType.SIMPLE_CHOICE_SWEEP, ValueType.CHOICE_SWEEP, ValueType.RANGE_SWEEP)


def check_sweep_dir(folder: str, name: str, hydra_args: list[str]) -> None:
    """Refuse (one line, exit code 2) a ``-m`` sweep whose ``hydra.sweep.dir`` cannot be made; a
    config that does not compose is left to Hydra's own message."""
    GlobalHydra.instance().clear()
    try:
        with initialize_config_dir(config_dir=folder, version_base="1.3"):
            cfg = compose(config_name=name, overrides=hydra_args, return_hydra_config=True)
        check_output_dir("hydra.sweep.dir", cfg)
    except ConfigError as exc:
        _fail(str(exc))
    except Exception:  # Hydra reports its own composition errors when it starts
        return
    finally:
        GlobalHydra.instance().clear()


def check_output_dir(key: str, cfg: DictConfig) -> None:
    """The output folder ``key`` (``hydra.run.dir`` or ``hydra.sweep.dir``) of the composed ``cfg``
    must be creatable: its nearest existing ancestor a folder this process may write into."""
    path = Path(OmegaConf.select(cfg, key)).absolute()
    existing = next(p for p in (path, *path.parents) if p.exists())
    if not existing.is_dir():
        raise ConfigError(key, str(path), f"{existing} is not a folder; choose an output folder that can be created")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise ConfigError(key, str(path), f"{existing} is not writable; choose a folder you can write into")
    try:  # permissions can say yes where the file system says no (root on /proc, a read-only mount)
        os.rmdir(tempfile.mkdtemp(prefix=".quadest-probe-", dir=existing))
    except OSError as exc:
        raise ConfigError(
            key, str(path), f"{existing} takes no new folder ({exc.strerror}); choose a folder you can write into"
        ) from None


def _cells(overrides: list[str]) -> list[list[str]]:
    """The override lists to check: the overrides as given when none sweeps; else each value of
    each sweep once (``key=a,b``, ``range(...)``), the other sweeps at their first value. A sweep
    that cannot be listed (``interval(...)``, for a tuning sweeper) is left to Hydra."""
    parsed = OverridesParser.create().parse_overrides(overrides)
    swept = {i: p for i, p in enumerate(parsed) if p.is_sweep_override()}
    if not swept or not all(p.value_type in _LISTED for p in swept.values()):
        return [overrides]
    values = {i: list(p.sweep_string_iterator()) for i, p in swept.items()}
    first = [f"{swept[i].get_key_element()}={values[i][0]}" if i in swept else o for i, o in enumerate(overrides)]
    cells = [first]
    for i, rest in values.items():
        cells += [[*first[:i], f"{swept[i].get_key_element()}={v}", *first[i + 1 :]] for v in rest[1:]]
    return cells


EXPERIMENTS = "experiments"  # the sweep files' folder, at the repository root


def experiment_files() -> dict[str, Path]:
    """The experiments that are primary configs of their own, ``experiments/NAME.yaml`` (the
    sweeps, with their launcher and callbacks), by name: those of ``./experiments`` (the clone the
    command runs in, as ``-cd experiments`` reads) first, then those beside the config tree (the
    repository's for an editable install, the wheel's copy otherwise: from any directory)."""
    found: dict[str, Path] = {}
    for folder in (Path.cwd() / EXPERIMENTS, Path(config_dir()).parent / EXPERIMENTS):
        for path in sorted(folder.glob("*.yaml")):
            found.setdefault(path.stem, path.resolve())
    return found


def group_experiments() -> list[str]:
    """The options of the config group ``experiment`` (``conf/experiment/``)."""
    return sorted(p.stem for p in (Path(config_dir()) / "experiment").glob("*.yaml"))


_PRIMARY_FLAGS = {"-cd", "--config-dir", "-cn", "--config-name", "-cp", "--config-path"}


def one_way(argv: list[str]) -> tuple[list[str], Path | None]:
    """``quadest experiment=NAME [overrides]``, the one way to run any checked-in experiment.

    A NAME of ``conf/experiment/`` is a group option: the argv is returned unchanged. A NAME of
    ``experiments/`` becomes Hydra's ``--config-dir DIR --config-name NAME`` and the other
    arguments, in order: exactly the run (its sweep, launcher and callbacks) and the records of
    ``quadest -cd experiments -cn NAME``. Returns the argv for Hydra and the experiment file (None
    when there is none). An unknown NAME, a NAME in both places, a sweep file among several
    experiments or beside ``-cd``/``-cn`` end with one line (exit code 2)."""
    position = next((i for i, arg in enumerate(argv) if arg.split("=", 1)[0] == "experiment"), None)
    if position is None:
        return argv, None
    value = argv[position].split("=", 1)[1]
    files, group = experiment_files(), group_experiments()
    plain = re.fullmatch(r"[\w,\[\] ]*", value)  # names, a comma list or a list; not choice(...), ${...}
    names = [v.strip() for v in value.strip("[]").split(",") if v.strip()] if plain else []
    unknown = [n for n in names if n not in files and n not in group and n != "null"]
    if unknown or (plain and not names):
        _fail(
            f"experiment={value}: no experiment {', '.join(unknown) or 'named'}; allowed: "
            f"{', '.join(sorted({*files, *group}))}"
        )
    sweeps = [n for n in names if n in files]
    if not sweeps:
        return argv, None
    both = [n for n in sweeps if n in group]
    if both:
        _fail(f"experiment={value}: {', '.join(both)} is both conf/experiment/ and {EXPERIMENTS}/; rename one")
    if len(names) > 1:
        _fail(f"experiment={value}: {sweeps[0]} ({EXPERIMENTS}/) runs alone; allowed: one experiment of {EXPERIMENTS}/")
    clash = [arg for arg in argv if arg.split("=", 1)[0] in _PRIMARY_FLAGS]
    if clash:
        _fail(f"experiment={value}: {clash[0]} cannot be combined with it; the experiment is its own config")
    path = files[sweeps[0]]
    rest = argv[:position] + argv[position + 1 :]
    return ["--config-dir", str(path.parent), "--config-name", path.stem, *rest], path


def _fail(message: str) -> None:
    print(f"quadest: error: {message}", file=sys.stderr)
    sys.exit(2)


def main() -> None:
    """Console-script entry point."""
    argv, primary = one_way(sys.argv[1:])
    precheck(argv if primary is None else argv[4:], primary)
    sys.argv[1:] = argv
    _main()
    _exit_if_cells_failed()


if __name__ == "__main__":
    main()
