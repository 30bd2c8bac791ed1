"""The command line shared by the tools that read one job's ``metrics.csv``
(``python -m quadest.aggregate.particle_count JOB_DIR``, ``python -m quadest.aggregate.ranking JOB_DIR``)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import pandas as pd


def read_job_metrics(tool: str, description: str, argv: list[str] | None) -> tuple[Path, pd.DataFrame] | None:
    """``JOB_DIR`` from ``argv`` and its ``metrics.csv``; ``None`` after a one-line error on
    stderr when the file does not exist (the caller exits with 2)."""
    parser = argparse.ArgumentParser(prog=f"python -m quadest.aggregate.{tool}", description=description)
    parser.add_argument("job_dir", type=Path, help="a job's output folder (holds metrics.csv)")
    job_dir = parser.parse_args(argv).job_dir
    metrics_csv = job_dir / "metrics.csv"
    if not metrics_csv.is_file():
        print(f"{tool}: error: {metrics_csv} does not exist", file=sys.stderr)
        return None
    return job_dir, pd.read_csv(metrics_csv)
