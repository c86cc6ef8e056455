"""Read the matcher names a package registers, without importing it.

Listing the built-ins this way keeps ``pin-match list`` cheap (no torch) and independent of
import order. It only works if every registration in the package is one the reader can see:
``@register_matcher("name")`` with the name written as a string, on a class at the top of a
file directly in the package's folder. Anything else (a name held in a variable, a plain
call, an alias, a file in a subfolder) would be found only once something imports it, so
the reader refuses it, naming the file and line, instead of listing an incomplete set.
"""

from __future__ import annotations

import ast
import functools
import importlib.util
from dataclasses import dataclass
from pathlib import Path

from pin_match.errors import PinMatchError

DECORATOR = "register_matcher"
HOW = f'write @{DECORATOR}("name") with the name as a string on a class at the top of the file'


class RegistrationError(PinMatchError, ValueError):
    """A registration the registry cannot read, or a matcher name claimed by two classes."""


@dataclass(frozen=True)
class Registration:
    """One ``@register_matcher("name")`` read from a file: the class that claims the name, and where."""

    module: str
    qualname: str
    path: Path
    line: int

    @property
    def dotted(self) -> str:
        return f"{self.module}.{self.qualname}"


@functools.cache
def scan_package(package: str) -> dict[str, Registration]:
    """Registered name -> its registration, for every file in the package's folder (subfolders refused)."""
    try:
        spec = importlib.util.find_spec(package)
    except ModuleNotFoundError:  # a parent package of a dotted name is missing
        spec = None
    if spec is None:
        raise RegistrationError(f"cannot read the matchers of package {package!r}: it is not installed")
    if not spec.submodule_search_locations:
        raise RegistrationError(f"cannot read the matchers of package {package!r}: it is a module, not a package")
    found: dict[str, Registration] = {}
    for folder in map(Path, spec.submodule_search_locations):
        for path in sorted(folder.rglob("*.py")):
            text = path.read_text(encoding="utf-8")
            if DECORATOR not in text:
                continue
            tree = ast.parse(text, str(path))
            if path.parent != folder:
                _refuse_subfolder(tree, path, package, folder)
            for name, registration in _registrations(tree, f"{package}.{path.stem}", path):
                if name in found:
                    first = found[name]
                    raise RegistrationError(f"{path}:{registration.line}: matcher name {name!r} is already "
                                            f"registered at {first.path}:{first.line}; give one of them another name")
                found[name] = registration
    return found


def _refuse_subfolder(tree: ast.Module, path: Path, package: str, folder: Path) -> None:
    for node in ast.walk(tree):
        if _names_decorator(node):
            raise RegistrationError(f"{path}:{node.lineno}: {DECORATOR} in a subfolder of {package} is never read, "
                                    f"so its matcher is not listed; move the file up into {folder}")


def _registrations(tree: ast.Module, module: str, path: Path) -> list[tuple[str, Registration]]:
    readable: list[tuple[str, Registration]] = []
    seen: set[int] = set()  # the decorator nodes read above, by id
    for node in tree.body:
        for deco in node.decorator_list if isinstance(node, ast.ClassDef) else ():
            name = _literal_name(deco)
            if name is not None:
                readable.append((name, Registration(module, node.name, path, deco.lineno)))
                seen.add(id(deco.func))
    for node in ast.walk(tree):
        if _names_decorator(node) and id(node) not in seen:
            raise RegistrationError(f"{path}:{node.lineno}: {DECORATOR} used in a way the registry cannot read "
                                    f"without importing the file; {HOW}")
    return readable


def _literal_name(deco: ast.expr) -> str | None:
    """The name of ``@register_matcher("name")``; None for any other decorator."""
    if isinstance(deco, ast.Call) and _names_decorator(deco.func) and len(deco.args) == 1 and not deco.keywords:
        arg = deco.args[0]
        if isinstance(arg, ast.Constant) and isinstance(arg.value, str):
            return arg.value
    return None


def _names_decorator(node: ast.AST) -> bool:
    """``register_matcher`` as a name, an attribute (``contract.register_matcher``) or imported under another name."""
    if isinstance(node, ast.Name):
        return node.id == DECORATOR
    if isinstance(node, ast.Attribute):
        return node.attr == DECORATOR
    return isinstance(node, ast.alias) and node.name == DECORATOR and node.asname not in (None, DECORATOR)
