"""The ``quadest`` command: a Hydra app that runs one comparison per job.

``quadest`` runs the default comparison (EKF, UKF and SR-UKF on the thesis quadrotor) and prints
the per-state RMSE table, one line per estimator, one line per pair of estimators (the paired
comparison, ``docs/outputs.md``) and the output folder. Any key can be overridden
(``quadest estimator.srukf.alpha=0.1 sensor=tactical``) or swept (``quadest -m ...``). Data and
results computed before are loaded from the result cache (``docs/cache.md``).
"""

from __future__ import annotations

import dataclasses
import math
import re
import sys
from pathlib import Path

import hydra
from hydra import compose, initialize_config_dir
from hydra.core.global_hydra import GlobalHydra
from hydra.core.hydra_config import HydraConfig
from hydra.types import RunMode
from omegaconf import DictConfig

from quadest.app.job import run_job
from quadest.app.schema import register_schemas
from quadest.app.validate import validate
from quadest.config.paths import config_dir
from quadest.errors import ConfigError
from quadest.estimators.registry import discover
from quadest.evaluation.formatting import strict_json
from quadest.evaluation.objective import objective_value, validate_objective
from quadest.evaluation.pcrlb import pcrlb_caption

register_schemas()


@hydra.main(version_base="1.3", config_path=config_dir(), config_name="config")
def _main(cfg: DictConfig) -> float | None:
    """Run one job; with an ``objective`` configured, return it (what a tuning sweeper minimises;
    ``inf`` for a job that failed, so that the sweep goes on)."""
    hc = HydraConfig.get()
    out_dir = Path(hc.runtime.output_dir)
    multirun = hc.mode == RunMode.MULTIRUN
    failed = None if cfg.objective.estimator is None else math.inf
    try:
        validate_objective(cfg)
        summary = run_job(cfg, out_dir, list(hc.overrides.task))
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
    print(
        f"\n{summary['_caption']}"  # a flight-log replay (docs/replay.md)
        if "_caption" in summary
        else f"\nPer-state RMSE, mean ± std over {cfg.runs} Monte Carlo runs (per-run RMSE over time; diverged runs "
        f"excluded).\n{pcrlb_caption(cfg.model.name)}"
    )
    print(summary["_table"].to_string(index=False))
    # NEES dof: the error state's (a closed-loop or replay summary has vector states, no error_names)
    n, m = len(summary.get("error_names", summary["state_names"])), len(summary["measurement_names"])
    for name, est in summary["estimators"].items():
        nis = (
            f"mean NIS {_fmt(est['mean_nis'])} ({m} dof, {_pct(est['nis_in_band'])} in band)"
            if m
            else "NIS per sensor " + ", ".join(f"{s} {_fmt(v)}" for s, v in est.get("nis_by_sensor", {}).items())
        )
        print(f"  {name:>8s}: {est['diverged']} of {cfg.runs} runs diverged, mean NEES {_fmt(est['mean_nees'])} "
              f"({n} dof, {_pct(est['nees_in_band'])} of steps in the 95% band), {nis}, "
              f"{_fmt(est['step_time_us'], 1)} us/step/run"
              f"{' (from the cache)' if est['from_cache'] else ''}")  # fmt: skip
    if summary["_paired"]:
        print("\nPaired differences of per-run RMSE, estimator - reference, in % of the reference with the paired "
              "bootstrap 95% CI\n(paired_comparison.csv; Holm over all pairs x states; runs diverged in either "
              "excluded):")  # fmt: skip
        for line in summary["_paired"]:
            print(f"  {line}")
    print(f"\nOutputs: {out_dir}")
    if cfg.objective.estimator is None:
        return None
    value = objective_value(cfg.objective, summary)
    print(f"Objective ({cfg.objective.estimator}): {value:.6g}")
    return value


def _fmt(value: float | None, digits: int = 2) -> str:
    return "n/a" if value is None else f"{value:.{digits}f}"


def _pct(value: float | None) -> str:
    return "n/a" if value is None else f"{100 * value:.0f}%"


def _record_failure(out_dir: Path, reason: str) -> None:
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "summary.json").write_text(strict_json({"status": "failed", "error": reason}, indent=2))
    print(f"quadest: job failed: {reason}", file=sys.stderr)


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
    missing = re.search(r"Could not load '([\w/]+)/([^']+)'", message)
    if missing:
        group, name = missing.groups()
        problems = discover()[1] if group == "estimator" else {}
        if name in problems:
            return problems[name]
        options = sorted(p.stem for p in (Path(config_dir()) / group).glob("*.yaml"))
        message += f" Available options in '{group}': {', '.join(options)}"
    schema = getattr(cause, "object_type", None) or getattr(exc, "object_type", None)
    if schema is not None and dataclasses.is_dataclass(schema) and "not in" in message:
        message += f"; allowed keys: {', '.join(f.name for f in dataclasses.fields(schema))}"
    return message


def precheck(argv: list[str]) -> None:
    """Compose and validate a plain run's config before Hydra starts, so that a typo, a wrong
    type or a value out of range ends with one line and exit code 2, before any work."""
    if any(arg in _HYDRA_FLAGS or arg.startswith("--") for arg in argv):
        return
    overrides = [a for a in argv if not a.lstrip("+~").startswith(("hydra.", "hydra/"))]
    GlobalHydra.instance().clear()
    try:
        with initialize_config_dir(config_dir=config_dir(), version_base="1.3"):
            cfg = compose(config_name="config", overrides=overrides)
        validate(cfg)
        validate_objective(cfg)
    except ConfigError as exc:
        _fail(str(exc))
    except Exception as exc:  # Hydra/OmegaConf composition errors
        _fail(one_line(exc))
    finally:
        GlobalHydra.instance().clear()


def _fail(message: str) -> None:
    print(f"quadest: error: {message}", file=sys.stderr)
    sys.exit(2)


def main() -> None:
    """Console-script entry point."""
    precheck(sys.argv[1:])
    _main()


if __name__ == "__main__":
    main()
