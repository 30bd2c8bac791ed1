"""The ``quadest-aggregate SWEEP_DIR [--output full|compact]`` command: (re-)aggregate any sweep
folder, by default in the output its own config asks for (``multirun.yaml``)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from quadest.aggregate.report import OUTPUT_KEY, OUTPUTS, aggregate, sweep_output
from quadest.errors import ConfigError


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="quadest-aggregate", description="Aggregate a quadest sweep folder.")
    parser.add_argument("sweep_dir", type=Path, help="the multirun folder (holds 0/, 1/, ... and multirun.yaml)")
    parser.add_argument(
        "--output",
        choices=OUTPUTS,
        help=f"every table and figure, or the compact aggregate of a large grid (default: the sweep's {OUTPUT_KEY}, "
        "else full)",
    )
    args = parser.parse_args(argv)
    if not args.sweep_dir.is_dir():
        print(f"quadest-aggregate: error: {args.sweep_dir} is not a directory", file=sys.stderr)
        return 2
    try:
        output = args.output or sweep_output(args.sweep_dir)
    except ConfigError as exc:
        print(f"quadest-aggregate: error: {args.sweep_dir / 'multirun.yaml'}: {exc}", file=sys.stderr)
        return 2
    print(f"Aggregated: {aggregate(args.sweep_dir, output=output)}")
    return 0
