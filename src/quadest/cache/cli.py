"""The ``quadest-cache info|clear [--dir DIR]`` command: what the cache holds, and emptying it."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from quadest.cache.location import ENV_VAR, default_cache_dir
from quadest.cache.store import KINDS, CacheStore


def _megabytes(paths: list[Path]) -> float:
    return sum(p.stat().st_size for p in paths if p.exists()) / 1e6


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="quadest-cache", description="Inspect or empty the quadest result cache.")
    parser.add_argument("action", choices=["info", "clear"], help="info: entries and size; clear: delete them")
    parser.add_argument(
        "--dir", type=Path, default=None, help=f"the cache folder (default: ${ENV_VAR}, else ~/.cache/quadest)"
    )
    args = parser.parse_args(argv)
    root = (args.dir or default_cache_dir()).expanduser().absolute()
    if root.exists() and not root.is_dir():
        print(f"quadest-cache: error: {root} is not a directory", file=sys.stderr)
        return 2
    store = CacheStore(root)
    if args.action == "clear":
        print(f"Deleted {store.clear()} files from {root}")
        return 0
    print(f"Cache folder: {root}")
    for kind in KINDS:
        files = store.entries(kind)
        print(f"  {kind:>9s}: {len(files)} entries, {_megabytes(files):.1f} MB")
    leftovers = store.temporary_files()
    if leftovers:
        print(f"  temporary: {len(leftovers)} files of writers still running or killed, {_megabytes(leftovers):.1f} MB")
    return 0
