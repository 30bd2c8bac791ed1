"""Loading plugins from entry points, the same way for every kind (models, sensors): a plugin that
fails to import, breaks its kind's contract, is named unlike its entry point or reuses a built-in
name is reported with one line naming it, never raised (a broken third-party package must not take
quadest down); the caller refuses it only if it is selected."""

from __future__ import annotations

from collections.abc import Callable
from importlib.metadata import entry_points
from typing import Any


def load_entry_points(
    group: str,
    kind: str,
    builtin: dict[str, Any],
    problems_of: Callable[[Any], list[str]],
    name_of: Callable[[Any], str],
) -> tuple[dict[str, Any], dict[str, str]]:
    """``builtin`` plus the usable plugins of entry-point ``group``, by name, and one-line problems
    (name → text) of the others; ``kind`` names them in the texts ("model", "sensor"),
    ``problems_of(obj)`` lists what keeps a loaded object from the contract and ``name_of(obj)`` is
    the name it declares."""
    found, problems = dict(builtin), {}
    for ep in entry_points(group=group):
        where = f"entry point '{ep.name} = {ep.value}'" + (f" of {ep.dist.name}" if ep.dist else "")
        if ep.name in builtin:
            problems[ep.name] = f"{kind} plugin {where} collides with the built-in {kind} '{ep.name}'; rename it"
            continue
        try:
            obj = ep.load()
        except Exception as exc:
            problems[ep.name] = f"{kind} plugin {where} failed to import: {type(exc).__name__}: {exc}"
            continue
        issues = problems_of(obj)
        if not issues and name_of(obj) != ep.name:
            issues.append(f"it is named {name_of(obj)!r}, not {ep.name!r} as its entry point")
        if issues:
            problems[ep.name] = f"{kind} plugin {where} does not meet the contract: {'; '.join(issues)}"
            continue
        found[ep.name] = obj
    return found, problems
