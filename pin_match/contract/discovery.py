"""How plug-ins are found, one rule for the matcher registry and the data-source catalogue.

A built-in is a module of a package that registers what it holds as it is imported:
``import_package`` imports every module of that package once, those of its subpackages too (a
subfolder with an ``__init__.py``; an installed wheel holds one only where pyproject.toml lists
it among the packages, which tests/test_registry.py checks), so a new file there is all a
built-in needs and nothing lists the files. A third party declares its plug-ins in an
entry-point group: ``declared`` lists them by name without importing any, and refuses a name
that two installed packages declare rather than letting one silently win; ``load`` imports the
one asked for, naming the entry point when that fails.
"""

from __future__ import annotations

import importlib
import pkgutil
import types
from importlib.metadata import EntryPoint, entry_points
from typing import Any

from pin_match.errors import PinMatchError

_IMPORTED: set[str] = set()  # the packages whose modules are all imported


def import_package(package: str, error: type[PinMatchError], what: str) -> None:
    """Import every module of ``package`` once; one that cannot be imported is ``error`` naming it and ``what``."""
    if package in _IMPORTED:
        return
    _IMPORTED.add(package)  # first: a lookup made while the modules are imported must not start over
    try:
        for info in pkgutil.walk_packages(_import(package, package, error, what).__path__, f"{package}."):
            _import(info.name, package, error, what)
    except BaseException:
        _IMPORTED.discard(package)  # the next lookup tries again, and fails the same way
        raise


def _import(module: str, package: str, error: type[PinMatchError], what: str) -> types.ModuleType:
    try:
        return importlib.import_module(module)
    except ImportError as exc:  # a missing package or dependency; a bug in a module keeps its own traceback
        raise error(f"cannot import {module}, a module of the built-in {what} ({package}): {exc}") from exc


def declared(group: str, error: type[PinMatchError], what: str) -> dict[str, EntryPoint]:
    """Name -> entry point of every plug-in installed in ``group``; a name two of them declare is ``error``."""
    found: dict[str, EntryPoint] = {}
    for ep in entry_points(group=group):
        if ep.name in found and found[ep.name].value != ep.value:
            raise error(f"{what} {ep.name!r} is declared by two entry points, {found[ep.name].value} and {ep.value}; "
                        f"uninstall one of their packages")
        found[ep.name] = ep
    return found


def described(ep: EntryPoint) -> str:
    """An entry point as every message about it names it: its name, what it points at and its group."""
    return f"entry point {ep.name!r} ({ep.value}, group {ep.group})"


def load(ep: EntryPoint, error: type[PinMatchError], what: str) -> Any:
    """The object ``ep`` names; whatever importing it raises is ``error`` naming ``what`` and the entry point."""
    try:
        return ep.load()
    except Exception as exc:  # whatever importing a third party's module raises, it is that package's fault
        raise error(f"{what} {described(ep)} cannot be loaded: {type(exc).__name__}: {exc}") from exc
