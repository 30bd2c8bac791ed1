"""The ``quadest`` command: a Hydra app that runs one comparison per job.

``quadest`` runs the default comparison (EKF, UKF and SR-UKF on the thesis quadrotor) and prints
the per-state RMSE table and the output folder. Any key can be overridden
(``quadest estimator.srukf.alpha=0.1 sensor=tactical``) or swept (``quadest -m ...``).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import hydra
from hydra.core.hydra_config import HydraConfig
from hydra.types import RunMode
from omegaconf import DictConfig

from quadest.config.paths import config_dir
from quadest.config.schema import register_schemas
from quadest.errors import ConfigError
from quadest.job import run_job

register_schemas()


@hydra.main(version_base="1.3", config_path=config_dir(), config_name="config")
def _main(cfg: DictConfig) -> None:
    hc = HydraConfig.get()
    out_dir = Path(hc.runtime.output_dir)
    multirun = hc.mode == RunMode.MULTIRUN
    try:
        summary = run_job(cfg, out_dir, list(hc.overrides.task))
    except ConfigError as exc:
        if not multirun:
            print(f"quadest: error: {exc}", file=sys.stderr)
            sys.exit(2)
        _record_failure(out_dir, f"ConfigError: {exc}")
        return
    except Exception as exc:  # in a sweep, one bad cell must not lose the others
        if not multirun:
            raise
        _record_failure(out_dir, f"{type(exc).__name__}: {exc}")
        return
    print(f"\nPer-state RMSE, mean ± std over {cfg.runs} Monte Carlo runs "
          f"(per-run RMSE over time; diverged runs excluded):")
    print(summary["_table"].to_string(index=False))
    for name, est in summary["estimators"].items():
        print(f"  {name}: {est['diverged']} diverged, mean NEES {est['mean_nees']}, "
              f"mean NIS {est['mean_nis']}, {est['step_time_us']:.1f} us/step/run")
    print(f"\nOutputs: {out_dir}")


def _record_failure(out_dir: Path, reason: str) -> None:
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "summary.json").write_text(json.dumps({"status": "failed", "error": reason}, indent=2))
    print(f"quadest: job failed: {reason}", file=sys.stderr)


def main() -> None:
    """Console-script entry point."""
    _main()


if __name__ == "__main__":
    main()
