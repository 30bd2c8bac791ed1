"""Warnings a job prints before its work: one ``quadest: warning: ...`` line on stderr each, once
per process (a plain run validates its config twice: before Hydra starts and in the job)."""

from __future__ import annotations

import sys

_printed: set[str] = set()


def warn(message: str) -> None:
    """Print ``quadest: warning: <message>`` to stderr, unless this process printed it already."""
    if message not in _printed:
        _printed.add(message)
        print(f"quadest: warning: {message}", file=sys.stderr)
