"""One registry behaviour for every extension kind: estimators, models, sensors and scenarios
(docs/plugins.md, "Errors you may meet").

An extension comes from one of two places:

1. **The repository**: the registry imports every module of the kind's package once and asks
   the kind which of the module's objects declare themselves extensions (an estimator or sensor
   class that sets ``config_name``, a module-level model spec, a scenario class that sets its own
   ``name``), under which name.
2. **An installed package**: an entry point in the kind's group, whose name is the extension's
   name (``"ckf2 = mypkg.filters:CKF2"``).

Both go through the same checks, and each problem is one line naming the extension's origin and
the reason, never an exception (a broken package must not take quadest down):

- a module or entry point that fails to import;
- an object that breaks the kind's contract (:attr:`ExtensionKind.problems_of`), in the
  repository as in a plugin;
- an entry point whose object declares another name than the entry point's;
- two extensions with one name: two of the repository's or two plugins' are both refused and
  the line names both origins; a plugin named like a built-in is refused and the built-in stays.

:meth:`Found.refuse_selected` turns the problem of a selected extension into a
:class:`~quadest.errors.PluginError` and mentions the others once per process on stderr.
:meth:`Found.builtins` is the view of the repository's own extensions alone, whatever is
installed (what the repository's tests cover). :func:`missing_yaml` is the line for an extension
that is registered while its YAML is not on Hydra's search path (the application layer, which
composes the config, tells when).
"""

from __future__ import annotations

import importlib
import pkgutil
import sys
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from importlib.metadata import EntryPoint, entry_points
from types import ModuleType
from typing import Any

from quadest.errors import PluginError


@dataclass(frozen=True)
class ExtensionKind:
    """What the registry needs to know of one kind of extension.

    ``kind`` names it in messages ("estimator"); ``package`` is the package whose modules hold the
    built-ins; ``group`` the entry-point group of the plugins; ``declared(module)`` yields
    ``(name, attribute, object)`` for each object of ``module`` that declares itself an extension
    (defined there, not imported); ``problems_of(obj)`` lists what keeps ``obj`` from the contract
    (empty when it meets it); ``name_of(obj)``, where the object carries a name of its own, is that
    name (an entry point must agree with it); ``make(name, obj, origin)`` is the registry's entry
    of a usable extension (the object itself by default)."""

    kind: str
    package: str
    group: str
    declared: Callable[[ModuleType], Iterable[tuple[str, str, Any]]]
    problems_of: Callable[[Any], list[str]]
    name_of: Callable[[Any], str] | None = None
    make: Callable[[str, Any, str], Any] = lambda name, obj, origin: obj


@dataclass(frozen=True)
class Found:
    """The result of one scan: the usable extensions by name (the kind's entries, sorted), where
    each is from (``origins``: ``quadest.estimators.srukf.SRUKF``, or ``entry point 'ckf2 =
    mypkg.filters:CKF2' of mypkg``), which are the repository's own, and one line per name
    that is refused or collides."""

    kind: str
    usable: dict[str, Any]
    origins: dict[str, str]
    builtin: frozenset[str]
    problems: dict[str, str] = field(default_factory=dict)

    def builtins(self) -> dict[str, Any]:
        """The usable extensions of the repository alone, without any installed plugin."""
        return {name: entry for name, entry in self.usable.items() if name in self.builtin}

    def refuse_selected(self, selected: Iterable[str], key: str) -> None:
        """Raise the problem of the first selected name that is refused; write every other problem
        as one warning line on stderr, once per process.

        Raises:
            PluginError: a name of ``selected`` is refused (config key ``key``).
        """
        chosen = set(selected)
        for name, message in self.problems.items():
            if name in chosen and name not in self.usable:
                raise PluginError(name, message, key=key)
        for message in self.problems.values():
            if message not in _warned:
                _warned.add(message)
                print(f"quadest: warning: {message}", file=sys.stderr)


_warned: set[str] = set()


def missing_yaml(found: Found, name: str, yaml: str) -> str:
    """The line for extension ``name``, usable, while its YAML ``yaml`` (``estimator/ckf2.yaml``) is
    not on Hydra's config search path."""
    return (
        f"{found.kind} '{name}' is registered ({found.origins[name]}) but its YAML {yaml} is not on Hydra's "
        "config search path; an installed package ships it with a search-path plugin in its hydra_plugins/ "
        "folder (docs/plugins.md)"
    )


def _entry_point_origin(ep: EntryPoint) -> str:
    return f"entry point '{ep.name} = {ep.value}'" + (f" of {ep.dist.name}" if ep.dist else "")


def _add(problems: dict[str, str], name: str, message: str) -> None:
    problems[name] = f"{problems[name]}; {message}" if name in problems else message


def _scan_package(kind: ExtensionKind, problems: dict[str, str]) -> dict[str, list[tuple[str, Any]]]:
    """Every object the package's modules declare, by name: ``[(origin, object), ...]``, each
    object once (a spec imported by a second module is the same spec)."""
    package = importlib.import_module(kind.package)
    declared: dict[str, list[tuple[str, Any]]] = {}
    for info in pkgutil.iter_modules(package.__path__):
        module_name = f"{kind.package}.{info.name}"
        try:
            module = importlib.import_module(module_name)
        except Exception as exc:
            reason = f"{type(exc).__name__}: {exc}"
            _add(problems, module_name, f"{kind.kind} module {module_name} failed to import: {reason}")
            continue
        for name, attribute, obj in kind.declared(module):
            claims = declared.setdefault(name, [])
            if all(other is not obj for _, other in claims):
                claims.append((f"{module_name}.{attribute}", obj))
    return declared


def _builtins(kind: ExtensionKind, problems: dict[str, str]) -> tuple[dict[str, tuple[str, Any]], set[str]]:
    """The repository's usable extensions (name → (origin, object)) and every name it declares."""
    usable = {}
    declared = _scan_package(kind, problems)
    for name, claims in declared.items():
        if len(claims) > 1:
            origins = " and ".join(origin for origin, _ in claims)
            _add(problems, name, f"two {kind.kind}s are named '{name}': {origins}; rename one")
            continue
        origin, obj = claims[0]
        issues = kind.problems_of(obj)
        if issues:
            _add(problems, name, f"{kind.kind} {origin} does not meet the contract: {'; '.join(issues)}")
            continue
        usable[name] = (origin, obj)
    return usable, set(declared)


def _plugins(
    kind: ExtensionKind, builtin: dict[str, tuple[str, Any]], taken: set[str], problems: dict[str, str]
) -> dict[str, tuple[str, Any]]:
    """The usable plugins of the kind's entry-point group (name → (origin, object))."""
    by_name: dict[str, dict[str, EntryPoint]] = {}
    for ep in entry_points(group=kind.group):
        by_name.setdefault(ep.name, {}).setdefault(ep.value, ep)
    usable = {}
    for name, eps in by_name.items():
        origins = " and ".join(_entry_point_origin(ep) for ep in eps.values())
        if name in taken:
            where = f" ({builtin[name][0]})" if name in builtin else ""
            clash = f"collides with the built-in {kind.kind} '{name}'{where}; rename it"
            _add(problems, name, f"{kind.kind} plugin {origins} {clash}")
            continue
        if len(eps) > 1:
            _add(problems, name, f"two {kind.kind} plugins are named '{name}': {origins}; uninstall or rename one")
            continue
        (ep,) = eps.values()
        try:
            obj = ep.load()
        except Exception as exc:
            _add(problems, name, f"{kind.kind} plugin {origins} failed to import: {type(exc).__name__}: {exc}")
            continue
        issues = kind.problems_of(obj)
        if not issues and kind.name_of is not None and kind.name_of(obj) != name:
            issues.append(f"it is named {kind.name_of(obj)!r}, not {name!r} as its entry point")
        if issues:
            _add(problems, name, f"{kind.kind} plugin {origins} does not meet the contract: {'; '.join(issues)}")
            continue
        usable[name] = (origins, obj)
    return usable


def scan(kind: ExtensionKind) -> Found:
    """Every extension of ``kind``: the package's modules scanned once, then its entry points
    (module docstring)."""
    problems: dict[str, str] = {}
    builtin, taken = _builtins(kind, problems)
    found = {**builtin, **_plugins(kind, builtin, taken, problems)}
    return Found(
        kind=kind.kind,
        usable={name: kind.make(name, obj, origin) for name, (origin, obj) in sorted(found.items())},
        origins={name: origin for name, (origin, _) in found.items()},
        builtin=frozenset(builtin),
        problems=problems,
    )
