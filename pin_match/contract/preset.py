"""Named variants of one matcher as data: ``class Name(Base, preset=Preset(...))``.

``Matcher.__init_subclass__`` hands the ``preset=`` of a class statement to ``Preset.apply_to``,
which sets the class's config defaults and class data. Plug-ins import ``Preset`` from
``pin_match.contract``.
"""

from __future__ import annotations

import copy
import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from pin_match.contract.matcher import ConfigError, Matcher, MatcherConfig
from pin_match.contract.weights import WeightsSpec


@dataclass(frozen=True)
class Preset:
    """What one named variant sets: config defaults, weights, default sigma, and its paper when not the matcher's.

    Variants of a matcher (EfficientNet-Lite0, -Lite1, -Lite2; DINO and DINOv2) differ only in
    a few config defaults (the network, its input size), their weights, their default sigma
    and paper. As in timm's table of model configs, a matcher module keeps one class with the
    algorithm and a table of presets; each name is still a class statement, because a name is
    registered by decorating a class as its module is imported (``contract.registry``), and a
    Dask worker rebuilds a matcher from its class pickled by reference::

        @register_matcher("effnet-lite1")
        class EffnetLite1Matcher(EffnetMatcher, preset=EFFNET_PRESETS["effnet-lite1"]):
            ...  # a docstring only

    The preset's config defaults become the class's ``Config`` (a subclass of the base's, nested
    as ``EffnetLite1Matcher.Config`` so it pickles by reference); a field keeps its help and hash
    flag, and a dict or list value is copied into each new config. A matcher id hashes the config's
    values, not its class, so a variant turned into a preset keeps its id. A class whose body sets
    a ``default_sigma`` other than its preset's is refused: one of the two would silently lose.
    """

    config: Mapping[str, Any] = field(default_factory=dict)
    weights_spec: WeightsSpec | None = None
    default_sigma: float | None = None
    paper: str | None = None

    def apply_to(self, cls: type[Matcher]) -> None:
        """Set the preset on ``cls`` (``Matcher.__init_subclass__`` calls it for ``preset=``)."""
        own = vars(cls).get("default_sigma")
        if own is not None and self.default_sigma is not None and own != self.default_sigma:
            raise ConfigError(f"{cls.__module__}.{cls.__qualname__}: its body sets default_sigma={own!r} and its "
                              f"preset {self.default_sigma!r}; keep one of them")
        if self.config:
            cls.Config = config_with_defaults(cls.Config, self.config, cls)
        for attr in ("weights_spec", "default_sigma", "paper"):
            if getattr(self, attr) is not None:
                setattr(cls, attr, getattr(self, attr))


def config_with_defaults(base: type[MatcherConfig], defaults: Mapping[str, Any],
                         owner: type) -> type[MatcherConfig]:
    """A subclass of ``base`` whose fields named in ``defaults`` default to those values, nested in ``owner``."""
    fields = {f.name: f for f in dataclasses.fields(base)}
    unknown = sorted(set(defaults) - set(fields))
    if unknown:
        raise ConfigError(f"preset of {owner.__module__}.{owner.__qualname__}: {base.__name__} has no field "
                          f"{', '.join(unknown)}")
    changed = [(name, fields[name].type, default_field(value, fields[name].metadata))
               for name, value in defaults.items()]
    config = dataclasses.make_dataclass(owner.__name__.removesuffix("Matcher") + "Config", changed, bases=(base,))
    config.__module__, config.__qualname__ = owner.__module__, f"{owner.__qualname__}.Config"
    config.__doc__ = f"{base.__name__} with {owner.__name__}'s defaults: " + \
        ", ".join(f"{k}={v!r}" for k, v in defaults.items())
    return config


def default_field(value: Any, metadata: Mapping[str, Any]) -> Any:
    """A field defaulting to ``value``; a mutable one (dict, list: unhashable) is copied for each config."""
    if type(value).__hash__ is not None:
        return field(default=value, metadata=metadata)
    frozen = copy.deepcopy(value)  # later changes to the preset's own value do not reach the class
    return field(default_factory=lambda: copy.deepcopy(frozen), metadata=metadata)
