"""Find matchers by name: built-ins, anything decorated in a loaded module, and entry points.

A built-in is found by reading the ``@register_matcher("name")`` decorators in the files of
the built-in package, without importing them: listing names stays cheap (no torch), and a
name never fails because its module was not imported yet. Heavy libraries load only when
such a matcher is asked for. Third-party packages add matchers through the
``pin_match.matchers`` entry-point group.
"""

from __future__ import annotations

import ast
import dataclasses
import difflib
import fnmatch
import functools
import importlib
import importlib.util
import json
import types
import typing
from collections.abc import Callable
from importlib.metadata import entry_points
from pathlib import Path
from typing import Any

from pin_match.contract.matcher import ConfigError, Matcher, MatcherConfig, class_problems
from pin_match.errors import PinMatchError

ENTRY_POINT_GROUP = "pin_match.matchers"

# the package of the built-in plug-ins (the top-level matchers/ folder); its files are read, not imported, to list
# their names, so a new file there with @register_matcher is all a built-in needs
BUILTIN_PACKAGE = "pin_match.matchers"

_REGISTRY: dict[str, type[Matcher]] = {}


class UnknownMatcherError(PinMatchError, KeyError):
    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0])


def register_matcher(name: str, *, overwrite: bool = False) -> Callable[[type[Matcher]], type[Matcher]]:
    """Class decorator: ``@register_matcher("sift")`` makes the class reachable by name."""

    def deco(cls: type[Matcher]) -> type[Matcher]:
        if not (isinstance(cls, type) and issubclass(cls, Matcher)):
            raise TypeError(f"@register_matcher({name!r}) must decorate a Matcher subclass")
        problems = class_problems(cls)
        if problems:
            raise ConfigError(f"matcher {name!r} ({cls.__module__}.{cls.__qualname__}) does not fit the matcher "
                              f"contract: {'; '.join(problems)}")
        existing = _REGISTRY.get(name)
        if existing is not None and existing is not cls and not overwrite and \
                existing.__qualname__ != cls.__qualname__:
            raise ConfigError(f"matcher name {name!r} is already registered by {existing.__module__}")
        if "name" not in vars(cls):
            # the first name a class is registered under is its own (ids and caches carry it);
            # later names (an entry point's, an alias) only point at it and never rename it
            cls.name = name
        _REGISTRY[name] = cls
        return cls

    return deco


def builtin_modules() -> dict[str, str]:
    """Registered name -> module of every built-in matcher."""
    return modules_registering(BUILTIN_PACKAGE)


@functools.cache
def modules_registering(package: str) -> dict[str, str]:
    """Registered name -> module of every ``@register_matcher("name")`` in the package's own files."""
    spec = importlib.util.find_spec(package)
    if spec is None or not spec.submodule_search_locations:
        return {}
    found = {}
    for folder in spec.submodule_search_locations:
        for path in sorted(Path(folder).glob("*.py")):
            text = path.read_text(encoding="utf-8")
            if "register_matcher" in text:
                found.update(dict.fromkeys(_decorated_names(text, str(path)), f"{package}.{path.stem}"))
    return found


def _decorated_names(source: str, filename: str) -> list[str]:
    names = []
    for node in ast.walk(ast.parse(source, filename)):
        if isinstance(node, ast.ClassDef):
            for deco in node.decorator_list:
                if isinstance(deco, ast.Call) and getattr(deco.func, "id", getattr(deco.func, "attr", None)) == \
                        "register_matcher" and deco.args and isinstance(deco.args[0], ast.Constant):
                    names.append(deco.args[0].value)
    return names


def _entry_points() -> dict[str, Any]:
    return {ep.name: ep for ep in entry_points(group=ENTRY_POINT_GROUP)}


def available_names() -> list[str]:
    return sorted(set(builtin_modules()) | set(_REGISTRY) | set(_entry_points()))


def list_matchers(pattern: str = "*") -> list[str]:
    """Registered names matching a shell-style pattern, e.g. ``list_matchers("clip*")``."""
    return [n for n in available_names() if fnmatch.fnmatchcase(n, pattern)]


def get_matcher_class(name: str) -> type[Matcher]:
    if name not in _REGISTRY:
        builtins = builtin_modules()
        if name in builtins:
            importlib.import_module(builtins[name])
        else:
            ep = _entry_points().get(name)
            if ep is not None:
                cls = ep.load()
                if name not in _REGISTRY:  # an entry point may name a class that is not decorated
                    register_matcher(name)(cls)
    if name not in _REGISTRY:
        close = difflib.get_close_matches(name, available_names(), n=3, cutoff=0.5)
        hint = f"; did you mean {', '.join(close)}?" if close else f"; known: {', '.join(available_names())}"
        raise UnknownMatcherError(f"unknown matcher {name!r}{hint}")
    return _REGISTRY[name]


def build_config(cls: type[Matcher], overrides: dict[str, Any]) -> MatcherConfig:
    """The matcher's defaults merged with the user's overrides (strings from the CLI are coerced).

    A dotted key ``part_cfg.img_size`` sets one key inside the dict field ``part_cfg`` (a
    composite's part config), on top of that field's default or of a whole dict given with it;
    its value is left to the part's own ``build_config`` to coerce.
    """
    fields = {f.name: f for f in dataclasses.fields(cls.Config)}
    hints = typing.get_type_hints(cls.Config)
    kwargs: dict[str, Any] = {}
    nested: dict[str, dict[str, Any]] = {}
    for key, value in overrides.items():
        name, dotted, inner = key.partition(".")
        if name not in fields:
            close = difflib.get_close_matches(name, list(fields), n=3, cutoff=0.5)
            hint = f"; did you mean {', '.join(close)}?" if close else f"; valid keys: {', '.join(fields)}"
            raise ConfigError(f"matcher {cls.name!r} has no config key {name!r}{hint}")
        if dotted:
            if typing.get_origin(hints[name]) is not dict:
                raise ConfigError(f"matcher {cls.name!r}: config key {name!r} is not a dict, so {key!r} sets nothing")
            nested.setdefault(name, {})[inner] = value
        else:
            kwargs[name] = _coerce(key, value, hints[name]) if isinstance(value, str) else value
    for name, inner in nested.items():
        kwargs[name] = {**kwargs.get(name, _default(fields[name])), **inner}
    return cls.Config(**kwargs)


def _default(f: dataclasses.Field) -> Any:
    return f.default_factory() if f.default_factory is not dataclasses.MISSING else f.default


def _coerce(key: str, text: str, hint: Any) -> Any:
    options = typing.get_args(hint) if typing.get_origin(hint) in (typing.Union, types.UnionType) else (hint,)
    if type(None) in options and text.lower() in ("none", "null", ""):
        return None
    for typ in options:
        try:
            return _coerce_to(key, text, typ)
        except (ValueError, KeyError, ConfigError):
            continue
    raise ConfigError(f"config key {key!r}: cannot read {text!r} as {hint}")


def _coerce_to(key: str, text: str, typ: Any) -> Any:
    origin = typing.get_origin(typ)
    if origin in (tuple, list):
        item = next((a for a in typing.get_args(typ) if a is not Ellipsis), str)
        return origin(_coerce(key, x.strip(), item) for x in text.split(",") if x.strip())
    if origin is dict:  # a whole part config on the command line: a JSON object
        value = json.loads(text)
        if isinstance(value, dict):
            return value
    elif typ is bool:
        return {"1": True, "true": True, "yes": True, "on": True,
                "0": False, "false": False, "no": False, "off": False}[text.lower()]
    elif typ in (int, float, str):
        return typ(text)
    raise ValueError(text)


def parse_overrides(pairs: list[str] | None) -> dict[str, str]:
    """``["k=v", ...]`` from ``--cfg`` into a dict."""
    out = {}
    for pair in pairs or []:
        key, sep, value = pair.partition("=")
        if not sep or not key:
            raise ConfigError(f"--cfg {pair!r}: expected key=value")
        out[key.strip()] = value.strip()
    return out


def with_weights(overrides: dict[str, Any] | None, weights: str | None) -> dict[str, Any]:
    """Config overrides plus a local ``weights`` file or folder (``--weights``); it wins over a ``weights`` key."""
    merged = dict(overrides or {})
    if weights is not None:
        merged["weights"] = weights
    return merged


def create_matcher(name: str, **overrides: Any) -> Matcher:
    """Instantiate a matcher by name. Never touches the network: weights load lazily."""
    cls = get_matcher_class(name)
    return cls(build_config(cls, overrides))
