"""Find matchers by name: a class decorated with ``@register_matcher("name")`` registers itself at import.

That is timm's registry, plainly: importing a module registers what it decorates. The built-ins
are the modules of ``pin_match.matchers`` (the top-level ``matchers/`` folder, subpackages
included: ``discovery``), all imported the first time a name is listed or asked for, so a new
file there is all a built-in needs and no rule says how the decorator must be written. Importing
them costs what torch costs (docs/performance.md); ``pin-match list`` builds every matcher to show
its modality, sigma and weights, so it would import them anyway. Third-party packages add matchers
through the ``pin_match.matchers`` entry-point group, imported only when their name is asked for
(``discovery.load``, the data sources' loader too). A name belongs to one class: a second class
claiming it (a plug-in taking a built-in's name, two entry points, two decorated modules) is
refused, naming both, instead of the last one silently winning.
"""

from __future__ import annotations

import dataclasses
import difflib
import fnmatch
import json
import types
import typing
from collections.abc import Callable
from importlib.metadata import EntryPoint
from typing import Any

from pin_match.contract import discovery
from pin_match.contract.matcher import ConfigError, Matcher, MatcherConfig, class_problems
from pin_match.errors import PinMatchError

ENTRY_POINT_GROUP = "pin_match.matchers"

# the package of the built-in plug-ins (the top-level matchers/ folder); every module in it is imported before a name is
# listed or looked up, so a new file there with @register_matcher is all a built-in needs
BUILTIN_PACKAGE = "pin_match.matchers"

_REGISTRY: dict[str, type[Matcher]] = {}


class RegistrationError(PinMatchError, ValueError):
    """A matcher name claimed by two classes, or a built-in module that cannot be imported."""


class UnknownMatcherError(PinMatchError, KeyError):
    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0])


def register_matcher(name: str) -> Callable[[type[Matcher]], type[Matcher]]:
    """Class decorator: ``@register_matcher("sift")`` makes the class reachable by name."""

    def deco(cls: type[Matcher]) -> type[Matcher]:
        if not (isinstance(cls, type) and issubclass(cls, Matcher)):
            raise TypeError(f"@register_matcher({name!r}) must decorate a Matcher subclass")
        problems = class_problems(cls)
        if problems:
            raise ConfigError(f"matcher {name!r} ({cls.__module__}.{cls.__qualname__}) does not fit the matcher "
                              f"contract: {'; '.join(problems)}")
        _refuse_second_claim(name, _dotted(cls))
        if "name" not in vars(cls):
            # the first name a class is registered under is its own (ids and caches carry it);
            # later names (an entry point's, an alias) only point at it and never rename it
            cls.name = name
        _REGISTRY[name] = cls  # the same class again (its module imported anew) replaces itself
        return cls

    return deco


def _dotted(obj: Any) -> str:
    return f"{obj.__module__}.{obj.__qualname__}"


def _refuse_second_claim(name: str, claimant: str) -> None:
    if name not in _REGISTRY or _dotted(_REGISTRY[name]) == claimant:
        return
    owner = _dotted(_REGISTRY[name])
    if claimant.startswith(f"{BUILTIN_PACKAGE}."):  # a plug-in imported before the built-ins took a built-in's name
        raise RegistrationError(f"matcher name {name!r} belongs to the built-in {claimant}, but {owner} registered "
                                f"it first; {owner} needs another name")
    raise RegistrationError(f"matcher name {name!r} is already registered by {owner}; {claimant} needs another name")


def _import_builtins() -> None:
    discovery.import_package(BUILTIN_PACKAGE, RegistrationError, "matchers")


def _entry_points() -> dict[str, EntryPoint]:
    return discovery.declared(ENTRY_POINT_GROUP, RegistrationError, "matcher name")


def _load(ep: EntryPoint) -> type[Matcher]:
    """The matcher class an entry point names, or what is wrong with the entry point."""
    cls = discovery.load(ep, RegistrationError, "matcher")
    if not (isinstance(cls, type) and issubclass(cls, Matcher)):
        named = _dotted(cls) if isinstance(cls, type) else f"a {type(cls).__name__}"
        raise RegistrationError(f"matcher {discovery.described(ep)} names {named}, not a Matcher subclass")
    return cls


def _check_entry_point(name: str, ep: EntryPoint) -> None:
    """Refuse an entry point whose name another class holds (it would be ignored without a word)."""
    if name in _REGISTRY and _dotted(_REGISTRY[name]) != f"{ep.module}.{ep.attr}":
        _refuse_second_claim(name, _dotted(_load(ep)))  # a re-exported class is the same class: load to know


def available_names() -> list[str]:
    _import_builtins()
    plugins = _entry_points()
    for name, ep in plugins.items():
        _check_entry_point(name, ep)
    return sorted(set(_REGISTRY) | set(plugins))


def list_matchers(pattern: str = "*") -> list[str]:
    """Registered names matching a shell-style pattern, e.g. ``list_matchers("clip*")``."""
    return [n for n in available_names() if fnmatch.fnmatchcase(n, pattern)]


def get_matcher_class(name: str) -> type[Matcher]:
    _import_builtins()
    if name not in _REGISTRY:
        ep = _entry_points().get(name)
        if ep is not None:
            cls = _load(ep)
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
