"""The ``quadest-aggregate SWEEP_DIR`` command: (re-)aggregate any sweep folder."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from quadest.aggregate.report import aggregate


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="quadest-aggregate", description="Aggregate a quadest sweep folder.")
    parser.add_argument("sweep_dir", type=Path, help="the multirun folder (holds 0/, 1/, ... and multirun.yaml)")
    args = parser.parse_args(argv)
    if not args.sweep_dir.is_dir():
        print(f"quadest-aggregate: error: {args.sweep_dir} is not a directory", file=sys.stderr)
        return 2
    print(f"Aggregated: {aggregate(args.sweep_dir)}")
    return 0
